// Python bindings of the scene renderer: `_core.Mesh` (a triangle mesh and its BVH) and
// `_core.RenderScene` (instances of clouds and meshes, materials, lamps; render()).
// splat_tracer/render/scene.py wraps both; every input is validated here too.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iterator>
#include <cstring>
#include <memory>
#include <mutex>
#include <vector>

#include "python/py_util.h"
#include "shade/integrator.h"

namespace splat::py {
namespace {

// ---------------------------------------------------------------------------------------
// Mesh

struct MeshObject {
    PyObject_HEAD
    TriangleMesh *mesh;
};

PyObject *Mesh_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"vertices", "triangles", "corner_normals", "material_index", "threads", "corner_uv",
                                   "corner_attributes", nullptr};
    PyObject *ov, *ot, *on = Py_None, *om = Py_None, *ouv = Py_None, *oattr = Py_None;
    int threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OO|OOiOO", const_cast<char **>(kwlist), &ov, &ot, &on, &om,
                                     &threads, &ouv, &oattr))
        return nullptr;
    if (!check_threads(threads)) return nullptr;
    View v, t, n, m, uv, attr;
    Py_ssize_t s3[2] = {-1, 3};
    if (!get_array(ov, "vertices", 'f', 2, s3, false, v)) return nullptr;
    if (!get_array(ot, "triangles", 'i', 2, s3, false, t)) return nullptr;
    const Py_ssize_t nt = t.dim(0);
    Py_ssize_t sn[3] = {nt, 3, 3}, s1[1] = {nt};
    if (on != Py_None && !get_array(on, "corner_normals", 'f', 3, sn, false, n)) return nullptr;
    if (om != Py_None && !get_array(om, "material_index", 'i', 1, s1, false, m)) return nullptr;
    Py_ssize_t suv[3] = {nt, 3, 2};
    if (ouv != Py_None && !get_array(ouv, "corner_uv", 'f', 3, suv, false, uv)) return nullptr;
    // The attributes the node programs read, per corner (TriangleMesh::set_attributes).
    Py_ssize_t sattr[3] = {nt, 3, -1};
    if (oattr != Py_None && !get_array(oattr, "corner_attributes", 'f', 3, sattr, false, attr)) return nullptr;
    TriangleMesh *mesh = nullptr;
    if (!without_gil([&] {
            mesh = new TriangleMesh(v.data<float>(), size_t(v.dim(0)), t.data<int32_t>(), size_t(nt),
                                    n.held ? n.data<float>() : nullptr, m.held ? m.data<int32_t>() : nullptr,
                                    threads, uv.held ? uv.data<float>() : nullptr);
            if (attr.held && attr.dim(2) > 0) mesh->set_attributes(attr.data<float>(), int(attr.dim(2)));
        })) {
        delete mesh;  // null: the constructor refused an input
        return nullptr;
    }
    auto alloc = reinterpret_cast<allocfunc>(PyType_GetSlot(type, Py_tp_alloc));
    PyObject *self = alloc(type, 0);
    if (!self) {
        delete mesh;
        return nullptr;
    }
    reinterpret_cast<MeshObject *>(self)->mesh = mesh;
    return self;
}

void Mesh_dealloc(PyObject *self) {
    delete reinterpret_cast<MeshObject *>(self)->mesh;
    PyTypeObject *type = Py_TYPE(self);
    reinterpret_cast<freefunc>(PyType_GetSlot(type, Py_tp_free))(self);
    Py_DECREF(type);
}

const TriangleMesh *as_mesh(PyObject *obj) {
    // Identified by its deallocator, not by a stored type: a second import of this binary
    // under another module name (the add-on as bl_ext.*.splat_tracer) makes a new Mesh type,
    // and Meshes of the first import were refused -- or, through a null type pointer, len()
    // segfaulted (see as_splat_scene).
    if (PyType_GetSlot(Py_TYPE(obj), Py_tp_dealloc) != reinterpret_cast<void *>(Mesh_dealloc)) return nullptr;
    return reinterpret_cast<MeshObject *>(obj)->mesh;
}

PyObject *Mesh_size(PyObject *self, void *) { return PyLong_FromSize_t(as_mesh(self)->size()); }

PyGetSetDef Mesh_getset[] = {
    {"size", Mesh_size, nullptr, "Number of triangles.", nullptr},
    {nullptr, nullptr, nullptr, nullptr, nullptr},
};

PyType_Slot Mesh_slots[] = {
    {Py_tp_new, reinterpret_cast<void *>(Mesh_new)},
    {Py_tp_dealloc, reinterpret_cast<void *>(Mesh_dealloc)},
    {Py_tp_getset, Mesh_getset},
    {Py_tp_doc, const_cast<char *>("Mesh(vertices, triangles, corner_normals=None, material_index=None, threads=0, corner_uv=None, "
                                   "corner_attributes=None)")},
    {0, nullptr},
};

PyType_Spec Mesh_spec = {"splat_tracer._core.Mesh", sizeof(MeshObject), 0, Py_TPFLAGS_DEFAULT, Mesh_slots};

// ---------------------------------------------------------------------------------------
// RenderScene

struct RenderSceneObject {
    PyObject_HEAD
    RenderScene *scene;
    PyObject *geometries;  // a tuple holding every Scene/Mesh the instances point into
    int threads;
};

Affine affine_of(const float *row) {
    Affine a;
    std::copy(row, row + 12, a.m);
    return a;
}

// Images already converted for this scene, by the Python object holding their pixels: a
// texture used by several materials is held once.
using ImageTable = std::vector<std::pair<PyObject *, std::shared_ptr<const TextureImage>>>;

// An image from Python: (pixels, srgb) with pixels (h, w, 4) uint8 or float32, bottom row first.
std::shared_ptr<const TextureImage> parse_image(PyObject *obj, ImageTable &table) {
    for (auto &entry : table)
        if (entry.first == obj) return entry.second;
    PyObject *opix;
    int srgb = 0;
    if (!PyTuple_Check(obj) || !PyArg_ParseTuple(obj, "Op", &opix, &srgb)) {
        PyErr_Clear();
        PyErr_SetString(PyExc_TypeError, "an image is a (pixels, srgb) tuple");
        return nullptr;
    }
    View bytes, floats;
    Py_ssize_t shape[3] = {-1, -1, 4};
    const bool is_bytes = get_array(opix, "image pixels", 'B', 3, shape, false, bytes);
    if (!is_bytes) {
        PyErr_Clear();
        if (!get_array(opix, "image pixels (uint8 or float32, h x w x 4)", 'f', 3, shape, false, floats)) return nullptr;
    }
    const View &pix = is_bytes ? bytes : floats;
    // Texel coordinates reach 5x a side (TextureImage::sample keeps u, v in -4..5): a side of
    // at most 2^24 keeps them far inside int (and is beyond any image Blender makes).
    if (pix.dim(0) > (1 << 24) || pix.dim(1) > (1 << 24)) {
        PyErr_SetString(PyExc_ValueError, "an image is too large (more than 16777216 pixels a side)");
        return nullptr;
    }
    std::shared_ptr<const TextureImage> image;
    try {
        if (is_bytes)
            image = std::make_shared<TextureImage>(int(pix.dim(1)), int(pix.dim(0)), pix.data<uint8_t>(), srgb != 0);
        else
            image = std::make_shared<TextureImage>(int(pix.dim(1)), int(pix.dim(0)), pix.data<float>(), srgb != 0);
    } catch (const InputError &e) {
        PyErr_SetString(PyExc_ValueError, e.what());
        return nullptr;
    }
    table.emplace_back(obj, image);
    return image;
}

// A node program from Python: (code int32 (n, kNodeWidth), data float32 (m,), outputs int32
// (Output::Count,)[, images: a sequence of parse_image tuples[, aovs: int32 (k, 3) rows of
// AovWrite]]) -- render/nodes.py Program.native(). Checked by NodeProgram::validate.
bool parse_program(PyObject *obj, const std::string &name, NodeProgram &prog, ImageTable &images) {
    PyObject *ocode, *odata, *oout, *oimages = nullptr, *oaovs = nullptr;
    if (!PyTuple_Check(obj) || !PyArg_ParseTuple(obj, "OOO|OO", &ocode, &odata, &oout, &oimages, &oaovs)) {
        PyErr_Clear();
        PyErr_Format(PyExc_TypeError, "%s: a node program is a (code, data, outputs[, images]) tuple", name.c_str());
        return false;
    }
    if (oimages && oimages != Py_None) {
        PyObject *seq = PySequence_Tuple(oimages);
        if (!seq) return false;
        for (Py_ssize_t i = 0; i < PyTuple_Size(seq); ++i) {
            auto image = parse_image(PyTuple_GetItem(seq, i), images);
            if (!image) {
                Py_DECREF(seq);
                return false;
            }
            prog.images.push_back(image);
        }
        Py_DECREF(seq);
    }
    View code, data, out;
    Py_ssize_t sc[2] = {-1, kNodeWidth}, sd[1] = {-1}, so[1] = {int(Output::Count)};
    if (!get_array(ocode, "node code", 'i', 2, sc, false, code) || !get_array(odata, "node data", 'f', 1, sd, false, data) ||
        !get_array(oout, "node outputs", 'i', 1, so, false, out))
        return false;
    if (oaovs && oaovs != Py_None) {
        View aovs;
        Py_ssize_t sa[2] = {-1, 3};
        if (!get_array(oaovs, "node AOVs", 'i', 2, sa, false, aovs)) return false;
        const int32_t *a = aovs.data<int32_t>();
        for (Py_ssize_t i = 0; i < aovs.dim(0); ++i) prog.aovs.push_back({a[3 * i], a[3 * i + 1], a[3 * i + 2]});
    }
    prog.name = name;
    prog.code.assign(code.data<int32_t>(), code.data<int32_t>() + code.dim(0) * kNodeWidth);
    prog.data.assign(data.data<float>(), data.data<float>() + data.dim(0));
    std::copy(out.data<int32_t>(), out.data<int32_t>() + int(Output::Count), prog.outputs);
    for (float v : prog.data)
        if (!within_range(v)) {
            PyErr_Format(PyExc_ValueError, "%s: a node constant is not finite or beyond 1e18", name.c_str());
            return false;
        }
    try {
        prog.validate();
    } catch (const InputError &e) {
        PyErr_SetString(PyExc_ValueError, e.what());
        return false;
    }
    return true;
}

// _core.run_nodes(code, data, outputs, images, globals, out): runs a node program at each row
// of `globals` (n, kGlobalFloats: render/nodes.py GLOBAL_FIELDS) into `out` (n, len(data)),
// the registers after the run; `attributes` (optional, (n, k) floats): the point attributes
// there (ShaderGlobals::attributes). For the evaluator's tests.
PyObject *run_nodes(PyObject *, PyObject *args) {
    PyObject *ocode, *odata, *oout, *oimages, *oglobals, *oregs, *oattr = Py_None;
    if (!PyArg_ParseTuple(args, "OOOOOO|O", &ocode, &odata, &oout, &oimages, &oglobals, &oregs, &oattr))
        return nullptr;
    PyObject *triple = PyTuple_Pack(4, ocode, odata, oout, oimages);
    if (!triple) return nullptr;
    NodeProgram prog;
    ImageTable images;
    const bool ok = parse_program(triple, "program", prog, images);
    Py_DECREF(triple);
    if (!ok) return nullptr;
    constexpr int kGlobalFloats = 42;
    View g, regs, code, data, outs;
    Py_ssize_t sg[2] = {-1, kGlobalFloats}, sc[2] = {-1, kNodeWidth}, sd[1] = {-1}, so[1] = {int(Output::Count)};
    if (!get_array(oglobals, "globals", 'f', 2, sg, false, g)) return nullptr;
    Py_ssize_t sr[2] = {g.dim(0), Py_ssize_t(prog.data.size())};
    if (!get_array(oregs, "out", 'f', 2, sr, true, regs) || !get_array(ocode, "code", 'i', 2, sc, false, code) ||
        !get_array(odata, "data", 'f', 1, sd, false, data) || !get_array(oout, "outputs", 'i', 1, so, false, outs) ||
        !check_separate({{regs, "out"}}, {{g, "globals"}, {code, "code"}, {data, "data"}, {outs, "outputs"}}))
        return nullptr;
    View attr;
    Py_ssize_t sa[2] = {g.dim(0), -1};
    if (oattr != Py_None && !get_array(oattr, "attributes", 'f', 2, sa, false, attr)) return nullptr;
    if (attr.held && attr.dim(1) > kMaxPointAttributes)
        return PyErr_Format(PyExc_ValueError, "attributes: at most %d per point", kMaxPointAttributes), nullptr;
    float r[kMaxNodeRegisters];
    for (Py_ssize_t i = 0; i < g.dim(0); ++i) {
        const float *x = g.data<float>() + kGlobalFloats * i;
        ShaderGlobals s;
        Vec3 *vecs[11] = {&s.P,  &s.N,  &s.Ng, &s.I, &s.object, &s.object_normal, &s.generated, &s.uv, &s.point_colour,
                          &s.tangent, &s.surface_normal};
        for (int k = 0; k < 11; ++k) *vecs[k] = Vec3(x[3 * k], x[3 * k + 1], x[3 * k + 2]);
        // The Bump node's offsets: the test's shading point is its own object space, texture
        // space and UV map, so every position-dependent global moves alike.
        for (int k = 0; k < 2; ++k) {
            const Vec3 d(x[33 + 3 * k], x[34 + 3 * k], x[35 + 3 * k]);
            s.bump[k] = {d, d, d, Vec3(d.x, d.y, 0.f), d, Vec3()};  // no camera: Window stays 0
        }
        s.point_alpha = x[39], s.backfacing = x[40], s.tangent_sign = x[41];
        if (attr.held) s.attributes = attr.data<float>() + i * attr.dim(1), s.attribute_count = int(attr.dim(1));
        prog.run(s, r);
        std::copy(r, r + prog.data.size(), regs.data<float>() + i * Py_ssize_t(prog.data.size()));
    }
    Py_RETURN_NONE;
}

// The most motion steps a transform may have: Cycles' 2^(7-1) x 2 + 1 for its largest
// Motion Steps (7), with room to spare.
constexpr Py_ssize_t kMaxMotionSteps = 1025;

// Motion steps (motion.h) from `count` rows of 12 doubles (row-major 3x4 transforms at
// evenly spaced times over the shutter), each finite, within the coordinate limit and
// invertible. Sets an exception and returns false otherwise.
bool motion_keys(const double *rows, Py_ssize_t count, const char *what, Py_ssize_t which,
                 std::vector<MotionKey> &keys) {
    if (count < 2 || count > kMaxMotionSteps)
        return PyErr_Format(PyExc_ValueError, "%s %zd: %zd motion steps (2..%zd)", what, which, count, kMaxMotionSteps),
               false;
    keys.resize(size_t(count));
    for (Py_ssize_t i = 0; i < count; ++i) {
        const double *m = rows + 12 * i;
        for (int k = 0; k < 12; ++k)
            if (!within_range(float(m[k])) || !std::isfinite(m[k]))
                return PyErr_Format(PyExc_ValueError, "%s %zd: motion step %zd is not finite or beyond 1e18", what,
                                    which, i),
                       false;
        if (!motion::decompose(m, keys[size_t(i)]))
            return PyErr_Format(PyExc_ValueError, "%s %zd: motion step %zd is singular", what, which, i), false;
    }
    motion::align_quaternions(keys.data(), int(count));
    return true;
}

PyObject *RenderScene_new(PyTypeObject *type, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"geometries", "geometry_index", "to_world", "to_object", "material_range",
                                   "visibility", "holdout", "pass_index", "materials", "lights", "threads",
                                   "shadow_catcher", "motion", "motion_range", "programs", "object_values", nullptr};
    PyObject *ogeo, *oidx, *ow, *oo, *orange, *ovis, *ohold, *opass, *omat, *olight, *ocatch = Py_None,
             *omotion = Py_None, *omrange = Py_None, *oprog = Py_None, *oobj = Py_None;
    int threads = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOOOOOOOOO|iOOOOO", const_cast<char **>(kwlist), &ogeo, &oidx, &ow,
                                     &oo, &orange, &ovis, &ohold, &opass, &omat, &olight, &threads, &ocatch, &omotion,
                                     &omrange, &oprog, &oobj))
        return nullptr;
    if (!check_threads(threads)) return nullptr;
    PyObject *geometries = PySequence_Tuple(ogeo);
    if (!geometries) return nullptr;
    std::unique_ptr<PyObject, void (*)(PyObject *)> hold(geometries, [](PyObject *o) { Py_XDECREF(o); });
    const Py_ssize_t n_geo = PyTuple_Size(geometries);
    View idx, w, o, range, vis, holdout, pass, mat, light, catcher, motion, mrange;
    Py_ssize_t s1[1] = {-1};
    if (!get_array(oidx, "geometry_index", 'i', 1, s1, false, idx)) return nullptr;
    const Py_ssize_t n = idx.dim(0);
    Py_ssize_t s12[2] = {n, 12}, s2[2] = {n, 2}, sn[1] = {n}, sm[2] = {-1, kMaterialFields},
               sl[2] = {-1, kLightFields};
    if (!get_array(ow, "to_world", 'f', 2, s12, false, w) || !get_array(oo, "to_object", 'f', 2, s12, false, o) ||
        !get_array(orange, "material_range", 'i', 2, s2, false, range) ||
        !get_array(ovis, "visibility", 'i', 1, sn, false, vis) ||
        !get_array(ohold, "holdout", 'B', 1, sn, false, holdout) ||
        !get_array(opass, "pass_index", 'f', 1, sn, false, pass) ||
        !get_array(omat, "materials", 'f', 2, sm, false, mat) || !get_array(olight, "lights", 'f', 2, sl, false, light) ||
        (ocatch != Py_None && !get_array(ocatch, "shadow_catcher", 'B', 1, sn, false, catcher)))
        return nullptr;
    // Motion blur: instance i's steps are rows [first, first + count) of `motion` (count 0:
    // it does not move). Both or neither.
    if ((omotion == Py_None) != (omrange == Py_None))
        return PyErr_Format(PyExc_TypeError, "motion and motion_range go together");
    Py_ssize_t sm12[2] = {-1, 12};
    if (omotion != Py_None && (!get_array(omotion, "motion", 'd', 2, sm12, false, motion) ||
                               !get_array(omrange, "motion_range", 'i', 2, s2, false, mrange)))
        return nullptr;
    // Object Info and object attributes: one row per instance (ShaderGlobals::object_values).
    View objv;
    Py_ssize_t sobj[2] = {n, -1};
    if (oobj != Py_None && !get_array(oobj, "object_values", 'f', 2, sobj, false, objv)) return nullptr;
    if (objv.held && objv.dim(1) > kMaxObjectValues)
        return PyErr_Format(PyExc_ValueError, "object_values: at most %d per instance", kMaxObjectValues);
    const Py_ssize_t n_mat = mat.dim(0), n_light = light.dim(0);

    std::vector<Instance> instances(static_cast<size_t>(n));
    for (Py_ssize_t i = 0; i < n; ++i) {
        const int32_t g = idx.data<int32_t>()[i];
        if (g < 0 || g >= n_geo) return PyErr_Format(PyExc_ValueError, "instance %zd: geometry index %d out of range", i, g);
        PyObject *geo = PyTuple_GetItem(geometries, g);
        Instance &inst = instances[size_t(i)];
        inst.splats = as_splat_scene(geo);
        inst.mesh = inst.splats ? nullptr : as_mesh(geo);
        if (!inst.splats && !inst.mesh)
            return PyErr_Format(PyExc_TypeError, "geometry %d is neither a Scene (splats) nor a Mesh", g);
        for (int k = 0; k < 12; ++k)
            if (!within_range(w.data<float>()[12 * i + k]) || !within_range(o.data<float>()[12 * i + k]))
                return PyErr_Format(PyExc_ValueError, "instance %zd: transform is not finite or beyond 1e18", i);
        inst.to_world = affine_of(w.data<float>() + 12 * i);
        inst.to_object = affine_of(o.data<float>() + 12 * i);
        const int32_t first = range.data<int32_t>()[2 * i], count = range.data<int32_t>()[2 * i + 1];
        if (first < 0 || count < 1 || int64_t(first) + count > n_mat)
            return PyErr_Format(PyExc_ValueError, "instance %zd: material range (%d, %d) is not inside the %zd materials",
                                i, first, count, n_mat);
        inst.material_offset = first, inst.material_count = count;
        inst.visibility = uint32_t(vis.data<int32_t>()[i]) & kVisAll;
        inst.holdout = holdout.data<uint8_t>()[i] != 0;
        inst.shadow_catcher = catcher.held && catcher.data<uint8_t>()[i] != 0;
        inst.pass_index = pass.data<float>()[i];
        if (objv.held) {
            const float *row = objv.data<float>() + objv.dim(1) * i;
            for (Py_ssize_t k = 0; k < objv.dim(1); ++k)
                if (!std::isfinite(row[k]))
                    return PyErr_Format(PyExc_ValueError, "instance %zd: object value %zd is not finite", i, k);
            inst.object_values.assign(row, row + objv.dim(1));
        }
        if (mrange.held) {
            const int32_t mfirst = mrange.data<int32_t>()[2 * i], mcount = mrange.data<int32_t>()[2 * i + 1];
            if (mcount == 0) continue;
            if (mfirst < 0 || mcount < 0 || int64_t(mfirst) + mcount > int64_t(motion.dim(0)))
                return PyErr_Format(PyExc_ValueError, "instance %zd: motion range (%d, %d) is not inside the %zd steps",
                                    i, mfirst, mcount, motion.dim(0));
            if (!motion_keys(motion.data<double>() + 12 * size_t(mfirst), mcount, "instance", i, inst.motion))
                return nullptr;
        }
    }
    std::vector<Material> materials(static_cast<size_t>(n_mat));
    for (Py_ssize_t i = 0; i < n_mat; ++i) {
        const float *r = mat.data<float>() + kMaterialFields * i;
        for (int k = 0; k < kMaterialFields; ++k)
            if (!std::isfinite(r[k])) return PyErr_Format(PyExc_ValueError, "material %zd: value %d is not finite", i, k);
        materials[size_t(i)] = Material::from_row(r);
        if (!(materials[size_t(i)].ior > 0.f)) return PyErr_Format(PyExc_ValueError, "material %zd: ior must be > 0", i);
    }
    // Node programs: one entry per material, None for a material without one.
    std::vector<NodeProgram> programs;
    if (oprog != Py_None) {
        PyObject *seq = PySequence_Tuple(oprog);
        if (!seq) return nullptr;
        std::unique_ptr<PyObject, void (*)(PyObject *)> hold_seq(seq, [](PyObject *o) { Py_XDECREF(o); });
        if (PyTuple_Size(seq) != n_mat)
            return PyErr_Format(PyExc_ValueError, "programs has %zd entries for %zd materials", PyTuple_Size(seq), n_mat);
        ImageTable images;
        for (Py_ssize_t i = 0; i < n_mat; ++i) {
            PyObject *item = PyTuple_GetItem(seq, i);
            if (item == Py_None) continue;
            NodeProgram prog;
            if (!parse_program(item, "material " + std::to_string(i), prog, images)) return nullptr;
            materials[size_t(i)].program = int(programs.size());
            programs.push_back(std::move(prog));
        }
    }
    std::vector<Light> lights(static_cast<size_t>(n_light));
    for (Py_ssize_t i = 0; i < n_light; ++i) {
        const float *r = light.data<float>() + kLightFields * i;
        for (int k = 0; k < kLightFields; ++k)
            if (!within_range(r[k])) return PyErr_Format(PyExc_ValueError, "light %zd: value %d is not finite", i, k);
        if (r[0] < 0 || r[0] > 3 || r[16] < 0 || r[16] > 3)
            return PyErr_Format(PyExc_ValueError, "light %zd: unknown type or shape", i);
        lights[size_t(i)] = Light::from_row(r);
    }
    RenderScene *scene = nullptr;
    if (!without_gil([&] { scene = new RenderScene(std::move(instances), std::move(materials), std::move(lights), threads,
                                                    std::move(programs)); }))
        return nullptr;
    auto alloc = reinterpret_cast<allocfunc>(PyType_GetSlot(type, Py_tp_alloc));
    PyObject *self = alloc(type, 0);
    if (!self) {
        delete scene;
        return nullptr;
    }
    auto *obj = reinterpret_cast<RenderSceneObject *>(self);
    obj->scene = scene;
    obj->geometries = hold.release();  // keeps the geometry alive as long as the scene
    obj->threads = threads;
    return self;
}

void RenderScene_dealloc(PyObject *self) {
    auto *obj = reinterpret_cast<RenderSceneObject *>(self);
    delete obj->scene;
    Py_XDECREF(obj->geometries);
    PyTypeObject *type = Py_TYPE(self);
    reinterpret_cast<freefunc>(PyType_GetSlot(type, Py_tp_free))(self);
    Py_DECREF(type);
}

// The light groups' map (IntegratorSettings::light_groups): the count is the light_groups
// buffer's planes; each lamp's and each instance's group (int32, -1: none) and the world's.
bool parse_light_groups(const RenderScene &scene, PyObject *ogroups, PyObject *olamps, PyObject *oinstances,
                        int world, LightGroupMap &map) {
    if (ogroups == Py_None) {
        if (olamps != Py_None || oinstances != Py_None || world != -1)
            return PyErr_Format(PyExc_TypeError, "light group assignments need the light_groups buffer"), false;
        return true;
    }
    View groups_view;  // only its shape is read here
    const Py_ssize_t any[4] = {-1, -1, -1, -1};
    if (!get_array(ogroups, "light_groups", 'f', 4, any, true, groups_view)) return false;
    const Py_ssize_t count = groups_view.buf.shape[0];
    if (count < 1 || count > kMaxLightGroups)
        return PyErr_Format(PyExc_ValueError, "light_groups must have 1..%d planes", kMaxLightGroups), false;
    map.count = int(count);
    struct {
        PyObject *obj;
        const char *name;
        size_t size;
        std::vector<int> *out;
    } lists[] = {{olamps, "light_group_lamps", scene.lights().size(), &map.lamp},
                 {oinstances, "light_group_instances", scene.instance_count(), &map.instance}};
    for (auto &l : lists) {
        if (l.obj == Py_None) continue;
        View v;
        const Py_ssize_t shape[1] = {Py_ssize_t(l.size)};
        if (!get_array(l.obj, l.name, 'i', 1, shape, false, v)) return false;
        const int32_t *g = v.data<int32_t>();
        l.out->assign(g, g + l.size);
        for (int x : *l.out)
            if (x < -1 || x >= map.count)
                return PyErr_Format(PyExc_ValueError, "%s: group %d outside -1..%d", l.name, x, map.count - 1), false;
    }
    if (world < -1 || world >= map.count)
        return PyErr_Format(PyExc_ValueError, "light_group_world %d outside -1..%d", world, map.count - 1), false;
    map.world = world;
    return true;
}

// The arrays of the Cryptomatte argument, held while the render runs.
struct CryptomatteViews {
    View out[CryptomatteFilm::kKinds], instance_ids, material_ids;
};

// render()'s `cryptomatte`: None, or (object, material, asset, slots, instance_ids,
// material_ids) -- each of the first three None or a writable float32 (h, w, 2 slots) buffer,
// slots in 1..kMaxCryptomatteSlots, instance_ids float32 (instances, 2) (each instance's
// object and asset id), material_ids float32 (materials,). Ids must be finite and not 0 (0
// marks a free slot; render/cryptomatte.py's ids never are).
bool parse_cryptomatte(PyObject *arg, const RenderScene &scene, int w, int h, CryptomatteFilm &film,
                       CryptomatteViews &views) {
    if (arg == Py_None) return true;
    // Blender's Levels go to 16 (pass_cryptomatte_depth's hard maximum).
    constexpr int kMaxCryptomatteSlots = 16;
    PyObject *kinds[CryptomatteFilm::kKinds], *oinst, *omat;
    int slots = 0;
    if (!PyArg_ParseTuple(arg, "OOOiOO;cryptomatte must be (object, material, asset, slots, instance_ids, "
                               "material_ids)",
                          &kinds[0], &kinds[1], &kinds[2], &slots, &oinst, &omat))
        return false;
    if (slots < 1 || slots > kMaxCryptomatteSlots)
        return PyErr_Format(PyExc_ValueError, "cryptomatte slots must be in 1..%d", kMaxCryptomatteSlots), false;
    const Py_ssize_t n_inst = Py_ssize_t(scene.instance_count()), n_mat = Py_ssize_t(scene.material_count());
    const Py_ssize_t inst_shape[2] = {n_inst, 2}, mat_shape[1] = {n_mat};
    if (!get_array(oinst, "cryptomatte instance_ids", 'f', 2, inst_shape, false, views.instance_ids) ||
        !get_array(omat, "cryptomatte material_ids", 'f', 1, mat_shape, false, views.material_ids))
        return false;
    const float *ids[2] = {views.instance_ids.data<float>(), views.material_ids.data<float>()};
    const size_t counts[2] = {size_t(n_inst) * 2, size_t(n_mat)};
    for (int a = 0; a < 2; ++a)
        for (size_t i = 0; i < counts[a]; ++i)
            if (!std::isfinite(ids[a][i]) || ids[a][i] == 0.f)
                return PyErr_Format(PyExc_ValueError, "cryptomatte ids must be finite and not 0"), false;
    static const char *names[CryptomatteFilm::kKinds] = {"cryptomatte object", "cryptomatte material",
                                                         "cryptomatte asset"};
    for (int k = 0; k < CryptomatteFilm::kKinds; ++k) {
        if (kinds[k] == Py_None) continue;
        const Py_ssize_t shape[3] = {h, w, 2 * Py_ssize_t(slots)};
        if (!get_array(kinds[k], names[k], 'f', 3, shape, true, views.out[k])) return false;
        film.out[k] = views.out[k].data<float>();
    }
    film.slots = slots, film.instance_ids = ids[0], film.material_ids = ids[1];
    return true;
}

// world_map: None, or (light, camera): the environment image lighting the scene and the one
// camera rays see (None: the same), each a height x width x 3 float32 array of finite values
// >= 0 (shade/environment.h's layout).
// The environment maps of the last renders, by content: building one costs ~30 ns a pixel
// (66 ms for 2048 x 1024), which the viewport would pay on every pass of every redraw; the
// images' bytes are hashed (~1 ns a byte) and compared in full before one is reused.
struct CachedMap {
    uint64_t hash = 0;
    int width = 0, height = 0;
    std::vector<float> rgb;
    std::shared_ptr<const EnvironmentMap> map;
};

std::shared_ptr<const EnvironmentMap> environment_map_of(const float *data, int w, int h) {
    static std::mutex mutex;
    static CachedMap cache[2];  // the world being edited and the one before it
    static int next = 0;
    const size_t n = size_t(w) * size_t(h) * 3;
    uint64_t hash = 1469598103934665603ull;  // FNV-1a over the words: a quick first check
    for (size_t k = 0; k < n; ++k) {
        uint32_t bits;
        std::memcpy(&bits, data + k, 4);
        hash = (hash ^ bits) * 1099511628211ull;
    }
    {
        std::lock_guard<std::mutex> lock(mutex);
        for (const CachedMap &c : cache)
            if (c.map && c.hash == hash && c.width == w && c.height == h &&
                std::memcmp(c.rgb.data(), data, n * sizeof(float)) == 0)
                return c.map;
    }
    auto map = std::make_shared<const EnvironmentMap>(data, w, h);
    std::lock_guard<std::mutex> lock(mutex);
    CachedMap &slot = cache[next];
    next = (next + 1) % 2;
    slot.hash = hash, slot.width = w, slot.height = h;
    slot.rgb.assign(data, data + n);
    slot.map = map;
    return map;
}

bool parse_world_map(PyObject *obj, std::shared_ptr<const EnvironmentMap> &light,
                     std::shared_ptr<const EnvironmentMap> &camera) {
    if (obj == Py_None) return true;
    if (!PyTuple_Check(obj) || PyTuple_Size(obj) != 2)
        return PyErr_SetString(PyExc_TypeError, "world_map must be None or a (light, camera) tuple"), false;
    for (int i = 0; i < 2; ++i) {
        PyObject *item = PyTuple_GetItem(obj, i);
        if (item == Py_None) {
            if (i == 0) return PyErr_SetString(PyExc_TypeError, "world_map's light image is required"), false;
            continue;
        }
        const char *name = i == 0 ? "world_map light" : "world_map camera";
        View view;
        const Py_ssize_t shape[3] = {-1, -1, 3};
        if (!get_array(item, name, 'f', 3, shape, false, view)) return false;
        const Py_ssize_t h = view.buf.shape[0], w = view.buf.shape[1];
        if (w < 2 || h < 2 || w > 65536 || h > 32768)
            return PyErr_Format(PyExc_ValueError, "%s must be 2..65536 wide and 2..32768 high", name), false;
        const float *data = view.data<float>();
        for (Py_ssize_t k = 0; k < w * h * 3; ++k)
            if (!(std::isfinite(data[k]) && data[k] >= 0.f))
                return PyErr_Format(PyExc_ValueError, "%s must be finite, >= 0", name), false;
        std::string message;
        std::shared_ptr<const EnvironmentMap> &target = i == 0 ? light : camera;
        if (PyObject *type = run_native([&] { target = environment_map_of(data, int(w), int(h)); }, message))
            return PyErr_SetString(type, message.c_str()), false;
    }
    return true;
}

PyObject *RenderScene_render(PyObject *self, PyObject *args, PyObject *kwargs) {
    static const char *kwlist[] = {"local_from_camera", "frustum", "orthographic", "width", "height", "window",
                                   "settings", "method", "world", "film_transparent", "combined", "depth", "normal",
                                   "diffcol", "emit", "shadow", "index", "splat_count", "threads", "progress",
                                   "tile_size", "packets", "lens", "shadow_catcher", "world_visibility", "position",
                                   "material_index", "mist", "environment", "mist_settings", "cryptomatte",
                                   "camera_motion", "shutter_table", "rolling_shutter_duration", "world_map",
                                   "light", "ao", "ao_distance", "light_groups", "light_group_lamps",
                                   "light_group_instances", "light_group_world", "uv", "aov", "instance",
                                   nullptr};
    PyObject *om, *ofrustum, *osettings, *ometh, *ocomb, *odepth = Py_None, *onormal = Py_None,
             *odiff = Py_None, *oemit = Py_None, *oshadow = Py_None, *oindex = Py_None, *ocount = Py_None,
             *progress = Py_None, *olens = Py_None, *ocatcher = Py_None, *oposition = Py_None,
             *omatindex = Py_None, *omist = Py_None, *oenv = Py_None, *ocrypto = Py_None, *ocammotion = Py_None,
             *oshutter = Py_None, *oworldmap = Py_None, *olight = Py_None, *oao = Py_None, *ogroups = Py_None,
             *ogroup_lamps = Py_None, *ogroup_instances = Py_None, *ouvpass = Py_None, *oaov = Py_None,
             *oinstance = Py_None;
    int orthographic, width, height, x0, y0, w, h, threads = 0, tile_size = kDefaultTileSize, transparent = 0,
        packets = 1, world_visibility = int(IntegratorSettings().world_visibility), group_world = -1;
    float world[3];
    IntegratorSettings cfg;
    if (!PyArg_ParseTupleAndKeywords(args, kwargs, "OOpii(iiii)OO(fff)pO|OOOOOOOiOipOOiOOOO(fff)OOOfOOOfOOOiOOO",
                                     const_cast<char **>(kwlist),
                                     &om, &ofrustum, &orthographic, &width, &height, &x0, &y0, &w, &h, &osettings,
                                     &ometh, &world[0], &world[1], &world[2], &transparent, &ocomb, &odepth, &onormal,
                                     &odiff, &oemit, &oshadow, &oindex, &ocount, &threads, &progress, &tile_size,
                                     &packets, &olens, &ocatcher, &world_visibility, &oposition, &omatindex, &omist, &oenv,
                                     &cfg.mist_start, &cfg.mist_inv_depth, &cfg.mist_falloff, &ocrypto, &ocammotion,
                                     &oshutter, &cfg.rolling_shutter_duration, &oworldmap, &olight, &oao,
                                     &cfg.ao_distance, &ogroups, &ogroup_lamps, &ogroup_instances, &group_world,
                                     &ouvpass, &oaov, &oinstance))
        return nullptr;
    if (!check_render_args(width, height, x0, y0, w, h, tile_size, threads, progress)) return nullptr;
    for (float v : world)
        if (!(std::isfinite(v) && v >= 0.f)) return PyErr_Format(PyExc_ValueError, "world radiance must be finite, >= 0");

    for (float v : {cfg.mist_start, cfg.mist_inv_depth, cfg.mist_falloff})
        if (!std::isfinite(v)) return PyErr_Format(PyExc_ValueError, "mist settings must be finite");
    if (cfg.mist_inv_depth < 0.f || cfg.mist_falloff <= 0.f)
        return PyErr_Format(PyExc_ValueError, "mist settings: 1 / depth must be >= 0 and the falloff > 0");
    unsigned int seed = 0;
    int headlight = 0, sky_ao = 0, adaptive = 0;
    if (!PyArg_ParseTuple(osettings, "iifiiiiiiIppifffpfidi;settings must be RenderSettings.pack()", &cfg.samples,
                          &cfg.filter_type, &cfg.filter_width, &cfg.shadow_samples, &cfg.max_bounces,
                          &cfg.diffuse_bounces, &cfg.glossy_bounces, &cfg.transmission_bounces,
                          &cfg.transparent_bounces, &seed, &headlight, &sky_ao, &cfg.ao_samples, &cfg.clamp_direct,
                          &cfg.clamp_indirect, &cfg.filter_glossy, &adaptive, &cfg.adaptive_threshold,
                          &cfg.adaptive_min_samples, &cfg.time_limit, &cfg.mesh_light_strategy))
        return nullptr;
    cfg.adaptive = adaptive != 0;
    for (float v : {cfg.clamp_direct, cfg.clamp_indirect, cfg.filter_glossy, cfg.adaptive_threshold})
        if (!(std::isfinite(v) && v >= 0.f))
            return PyErr_Format(PyExc_ValueError, "clamps, filter glossy and the noise threshold must be finite, >= 0");
    if (!(std::isfinite(cfg.time_limit) && cfg.time_limit >= 0.0) || cfg.adaptive_min_samples < 0)
        return PyErr_Format(PyExc_ValueError, "the time limit and minimum samples must be >= 0");
    if (cfg.mesh_light_strategy < 0 || cfg.mesh_light_strategy > 2)
        return PyErr_Format(PyExc_ValueError, "mesh_light_strategy must be 0..2 (see shading.RenderSettings)");
    if (!(std::isfinite(cfg.ao_distance) && cfg.ao_distance >= 0.f))
        return PyErr_Format(PyExc_ValueError, "ao_distance must be finite, >= 0");
    if (cfg.ao_samples < 1 || cfg.ao_samples > 1024) return PyErr_Format(PyExc_ValueError, "ao_samples must be in 1..1024");
    cfg.headlight = headlight != 0, cfg.sky_ao = sky_ao != 0;
    if (cfg.samples < 1 || cfg.samples > (1 << 16) || cfg.shadow_samples < 1 || cfg.shadow_samples > 1024 ||
        cfg.filter_type < 0 || cfg.filter_type > 2 || !(cfg.filter_width >= 0.01f && cfg.filter_width <= 10.f))
        return PyErr_Format(PyExc_ValueError, "settings out of range (see shading.RenderSettings)");
    for (int b : {cfg.max_bounces, cfg.diffuse_bounces, cfg.glossy_bounces, cfg.transmission_bounces,
                  cfg.transparent_bounces})
        if (b < 0 || b > 1024) return PyErr_Format(PyExc_ValueError, "bounce limits must be in 0..1024");
    cfg.seed = seed;
    if (!parse_method(ometh, cfg.method)) return nullptr;
    cfg.world = Vec3(world[0], world[1], world[2]);
    cfg.film_transparent = transparent != 0;
    if (world_visibility < 0 || world_visibility > int(kVisAll))
        return PyErr_Format(PyExc_ValueError, "world_visibility must be ray-kind bits in 0..%d", int(kVisAll));
    cfg.world_visibility = uint32_t(world_visibility);
    std::shared_ptr<const EnvironmentMap> environment, camera_environment;
    if (!parse_world_map(oworldmap, environment, camera_environment)) return nullptr;
    if (environment) {
        cfg.environment = environment.get(), cfg.camera_environment = camera_environment.get();
        cfg.world = environment->mean();  // what the uniform world's uses (sky AO, "is the scene lit") see
    }
    cfg.tile_size = tile_size;
    cfg.packets = packets != 0;

    Camera cam;
    CameraViews cam_views;
    if (!parse_camera(om, ofrustum, orthographic, cam, cam_views) || !parse_lens(olens, cam)) return nullptr;
    // Motion blur: the camera's local_from_camera rows (S, 12) over the shutter, and the
    // shutter curve's table (K,) of times in [0, 1], non-decreasing.
    View cam_motion_view, shutter_view;
    std::vector<MotionKey> cam_motion;
    if (ocammotion != Py_None) {
        Py_ssize_t sm12[2] = {-1, 12};
        if (!get_array(ocammotion, "camera_motion", 'd', 2, sm12, false, cam_motion_view) ||
            !motion_keys(cam_motion_view.data<double>(), cam_motion_view.dim(0), "camera", 0, cam_motion))
            return nullptr;
        cam.motion = cam_motion.data(), cam.motion_steps = int(cam_motion.size());
    }
    if (oshutter != Py_None) {
        Py_ssize_t sk[1] = {-1};
        if (!get_array(oshutter, "shutter_table", 'f', 1, sk, false, shutter_view)) return nullptr;
        const Py_ssize_t k = shutter_view.dim(0);
        const float *t = shutter_view.data<float>();
        if (k < 2 || k > 65536) return PyErr_Format(PyExc_ValueError, "shutter_table must have 2..65536 entries");
        for (Py_ssize_t i = 0; i < k; ++i)
            if (!(t[i] >= 0.f && t[i] <= 1.f) || (i > 0 && t[i] < t[i - 1]))
                return PyErr_Format(PyExc_ValueError, "shutter_table must be non-decreasing times in [0, 1]");
        cfg.shutter_table = t, cfg.shutter_table_size = int(k);
    }
    if (!(cfg.rolling_shutter_duration <= 1.f))  // negative: off; NaN refused
        return PyErr_Format(PyExc_ValueError, "rolling_shutter_duration must be <= 1 (negative: off)");

    Film film;
    film.width = width, film.height = height, film.x0 = x0, film.y0 = y0, film.w = w, film.h = h;
    struct Out {
        PyObject *obj;
        const char *name;
        int channels;
        float **target;
        View view;
        Py_ssize_t planes = 0;  // > 0: that many w x h x channels planes (-1: any number)
    } outs[] = {{ocomb, "combined", 4, &film.combined, {}},   {odepth, "depth", 1, &film.depth, {}},
                {onormal, "normal", 3, &film.normal, {}},     {odiff, "diffcol", 3, &film.diffcol, {}},
                {oemit, "emit", 3, &film.emit, {}},           {oshadow, "shadow", 3, &film.shadow, {}},
                {oindex, "index", 1, &film.index, {}},        {ocount, "splat_count", 1, &film.splat_count, {}},
                {ocatcher, "shadow_catcher", 3, &film.shadow_catcher, {}},
                {oposition, "position", 3, &film.position, {}},
                {omatindex, "material_index", 1, &film.material_index, {}},
                {omist, "mist", 1, &film.mist, {}},
                {oenv, "environment", 3, &film.environment, {}},
                {oao, "ao", 3, &film.ao, {}},
                {ouvpass, "uv", 3, &film.uv, {}},
                {oinstance, "instance", 1, &film.instance, {}},
                {olight, "light", 3, &film.light, {}, 3 * kLobes},
                {ogroups, "light_groups", 3, &film.light_groups, {}, -1}};
    for (Out &out : outs) {
        if (out.obj == Py_None) continue;
        if (out.planes != 0) {
            Py_ssize_t shape[4] = {out.planes, h, w, out.channels};
            if (!get_array(out.obj, out.name, 'f', 4, shape, true, out.view)) return nullptr;
        } else {
            Py_ssize_t shape[3] = {h, w, out.channels};
            if (!get_array(out.obj, out.name, 'f', out.channels == 1 ? 2 : 3, shape, true, out.view)) return nullptr;
        }
        *out.target = out.view.data<float>();
    }
    if (!parse_light_groups(*reinterpret_cast<RenderSceneObject *>(self)->scene, ogroups, ogroup_lamps,
                            ogroup_instances, group_world, cfg.light_groups))
        return nullptr;
    if (!film.combined) return PyErr_Format(PyExc_TypeError, "combined is required");
    auto *obj = reinterpret_cast<RenderSceneObject *>(self);
    const RenderScene &scene = *obj->scene;  // shared by renders running at once: never changed
    CryptomatteViews crypto_views;
    if (!parse_cryptomatte(ocrypto, scene, w, h, film.cryptomatte, crypto_views)) return nullptr;
    // Shader AOVs: (buffer float32 (h, w, channels), layout int32 (keys, 2) of [first channel or
    // -1, width 1 or 4], alpha threshold) -- render/scene.py render_arguments.
    View aov_view;
    if (oaov != Py_None) {
        PyObject *obuf, *olayout;
        float threshold;
        if (!PyTuple_Check(oaov) || !PyArg_ParseTuple(oaov, "OOf", &obuf, &olayout, &threshold)) {
            PyErr_Clear();
            return PyErr_Format(PyExc_TypeError, "aov must be a (buffer, layout, alpha_threshold) tuple");
        }
        if (!(std::isfinite(threshold) && threshold >= 0.f && threshold <= 1.f))
            return PyErr_Format(PyExc_ValueError, "the AOV alpha threshold must be in 0..1");
        View layout;
        Py_ssize_t sl[2] = {-1, 2};
        if (!get_array(olayout, "aov layout", 'i', 2, sl, false, layout)) return nullptr;
        Py_ssize_t sb[3] = {h, w, -1};
        if (!get_array(obuf, "aov", 'f', 3, sb, true, aov_view)) return nullptr;
        const int channels = int(aov_view.dim(2));
        const int32_t *l = layout.data<int32_t>();
        for (Py_ssize_t i = 0; i < layout.dim(0); ++i) {
            const int32_t first = l[2 * i], width = l[2 * i + 1];
            if (first >= 0 && !((width == 1 || width == 4) && int64_t(first) + width <= channels))
                return PyErr_Format(PyExc_ValueError, "aov layout row %zd: a pass of 1 or 4 channels within the buffer", i);
            film.aov.offset.push_back(first < 0 ? -1 : first), film.aov.width.push_back(width);
        }
        film.aov.alpha_threshold = threshold;
        if (channels > 0) film.aov.buffer = aov_view.data<float>(), film.aov.channels = channels;
        if (!check_separate({{aov_view, "aov"}}, {{cam_views.m, "local_from_camera"}, {cam_views.frustum, "frustum"}}))
            return nullptr;
        for (Out &out : outs)
            if (!check_separate({{aov_view, "aov"}, {out.view, out.name}}, {})) return nullptr;
        for (const View &out : crypto_views.out)
            if (!check_separate({{aov_view, "aov"}, {out, "a cryptomatte buffer"}},
                                {{crypto_views.instance_ids, "cryptomatte instance ids"},
                                 {crypto_views.material_ids, "cryptomatte material ids"}}))
                return nullptr;
    }
    for (size_t i = 0; i < std::size(outs); ++i) {
        if (!check_separate({{outs[i].view, outs[i].name}},
                            {{cam_views.m, "local_from_camera"}, {cam_views.frustum, "frustum"}}))
            return nullptr;
        for (size_t j = 0; j < i; ++j)
            if (!check_separate({{outs[i].view, outs[i].name}, {outs[j].view, outs[j].name}}, {})) return nullptr;
        for (const View &out : crypto_views.out)
            if (!check_separate({{out, "a cryptomatte buffer"}, {outs[i].view, outs[i].name}},
                                {{crypto_views.instance_ids, "cryptomatte instance ids"},
                                 {crypto_views.material_ids, "cryptomatte material ids"}}))
                return nullptr;
    }
    if (!check_separate({{crypto_views.out[0], "cryptomatte object"}, {crypto_views.out[1], "cryptomatte material"},
                         {crypto_views.out[2], "cryptomatte asset"}},
                        {{crypto_views.instance_ids, "cryptomatte instance ids"},
                         {crypto_views.material_ids, "cryptomatte material ids"},
                         {cam_views.m, "local_from_camera"}, {cam_views.frustum, "frustum"}}))
        return nullptr;
    RenderCounters counters;
    std::unique_ptr<Integrator> integrator;  // its constructor allocates: built where bad_alloc is caught
    std::string message;
    if (PyObject *type = run_native([&] { integrator = std::make_unique<Integrator>(scene, cam, film, cfg, counters); },
                                    message))
        return PyErr_SetString(type, message.c_str()), nullptr;
    const size_t tiles = integrator->tile_count();
    const int n_threads = threads > 0 ? threads : obj->threads;
    int done = 0, reached = cfg.samples;  // reached: the samples of the pixels that went furthest
    unsigned long long taken = (unsigned long long)cfg.samples * (unsigned long long)w * (unsigned long long)h;
    bool time_limited = false;
    if (!cfg.progressive()) {
        done = run_tiles(tiles, n_threads, progress,
                         [&](size_t t, const std::atomic<bool> &stop) { integrator->render_tile(t, &stop); });
        if (done < 0) return nullptr;
    } else {
        // Rounds of samples over the whole image, as Cycles' render scheduler: each ends where
        // a convergence check is due (adaptive sampling); with a time limit the first round is
        // one sample, and each next one as many as the time left fits at the last round's
        // pace (at most 4x the last, in case the pace was measured on a fast round), so the
        // limit is passed by at most about one sample's time.
        using Clock = std::chrono::steady_clock;
        const auto start = Clock::now();
        const size_t total = tiles * size_t(cfg.samples);
        int s = 0, round = cfg.time_limit > 0.0 ? 1 : cfg.samples;
        done = 1;
        while (s < cfg.samples) {
            const int n = integrator->align_samples(s, std::min(round, cfg.samples - s));
            const auto round_start = Clock::now();
            done = run_tiles(
                tiles, n_threads, progress,
                [&](size_t t, const std::atomic<bool> &stop) { integrator->render_tile_samples(t, s, s + n, &stop); },
                tiles * size_t(s), size_t(n), total);
            if (done < 0) return nullptr;
            if (done == 0) break;
            s += n;
            if (integrator->need_check(s - 1) && integrator->check_convergence() == 0) break;
            if (cfg.time_limit > 0.0) {
                const auto now = Clock::now();
                const double elapsed = std::chrono::duration<double>(now - start).count();
                if (elapsed >= cfg.time_limit) {
                    time_limited = s < cfg.samples;
                    break;
                }
                const double pace = std::chrono::duration<double>(now - round_start).count() / n;
                const double fit = pace > 0.0 ? (cfg.time_limit - elapsed) / pace : double(cfg.samples);
                round = int(std::clamp(fit, 1.0, 4.0 * n));
            }
        }
        reached = s;
        taken = integrator->finish();
    }
    auto n = [](const std::atomic<uint64_t> &a) { return (unsigned long long)a.load(); };
    return Py_BuildValue("(O{s:K,s:K,s:K,s:K,s:K,s:K,s:K,s:K,s:K,s:K,s:K,s:K,s:i,s:K,s:O})", done ? Py_True : Py_False,
                         "camera_rays", n(counters.camera), "shadow_rays", n(counters.shadow), "reflection_rays",
                         n(counters.reflection), "refraction_rays", n(counters.refraction), "diffuse_rays",
                         n(counters.diffuse), "transparent_rays", n(counters.transparent), "nodes", n(counters.nodes),
                         "disc_tests", n(counters.discs), "triangle_tests", n(counters.triangles), "layer_queries",
                         n(counters.layer_queries), "far_rejections", n(counters.far_rejections), "interpolations",
                         n(counters.interpolations), "samples_reached", reached, "samples_taken", taken,
                         "time_limited", time_limited ? Py_True : Py_False);
}

PyObject *RenderScene_instances(PyObject *self, void *) {
    return PyLong_FromSize_t(reinterpret_cast<RenderSceneObject *>(self)->scene->instance_count());
}

PyObject *RenderScene_mesh_lights(PyObject *self, PyObject *) {
    const MeshLights &lights = reinterpret_cast<RenderSceneObject *>(self)->scene->mesh_lights();
    std::vector<MeshLights::Pick> picks;
    std::string message;
    if (PyObject *type = run_native([&] { picks = lights.picks(); }, message))
        return PyErr_SetString(type, message.c_str()), nullptr;
    PyObject *list = PyList_New(Py_ssize_t(picks.size()));
    if (!list) return nullptr;
    for (size_t k = 0; k < picks.size(); ++k) {
        PyObject *item = Py_BuildValue("(iid)", picks[k].instance, int(picks[k].tri), picks[k].probability);
        if (!item) return Py_DECREF(list), nullptr;
        PyList_SetItem(list, Py_ssize_t(k), item);
    }
    return list;
}

PyMethodDef RenderScene_methods[] = {
    {"mesh_lights", RenderScene_mesh_lights, METH_NOARGS,
     "mesh_lights()\n--\n\nThe emissive triangles sampled as lights: [(instance, triangle, pick probability)]."},
    {"render", reinterpret_cast<PyCFunction>(reinterpret_cast<void (*)()>(RenderScene_render)),
     METH_VARARGS | METH_KEYWORDS,
     "render(local_from_camera, frustum, orthographic, width, height, window, settings, method, world, "
     "film_transparent, combined, depth=None, normal=None, diffcol=None, emit=None, shadow=None, index=None, splat_count=None, "
     "threads=0, progress=None, tile_size=32, packets=True, lens=None, shadow_catcher=None, world_visibility=15, "
     "position=None, material_index=None, mist=None, environment=None, mist_settings=(0, 0.01, 1), "
     "cryptomatte=None, camera_motion=None, shutter_table=None, rolling_shutter_duration=-1, world_map=None, "
     "light=None, ao=None, ao_distance=10, light_groups=None, light_group_lamps=None, light_group_instances=None, "
     "light_group_world=-1, uv=None, aov=None, instance=None)\n--\n\n"
     "Renders a window; returns (completed, counters). lens: None (a pinhole) or (radius, focus_distance, blades, "
     "rotation, ratio). shadow_catcher: the Shadow Catcher pass (its presence also takes the catchers' shadows out of "
     "combined, as Cycles). world_visibility: the ray kinds (visibility bits) that see the world. cryptomatte: None or "
     "(object, material, asset, slots, instance_ids, material_ids) (render/cryptomatte.py). camera_motion: "
     "None or (S, 12) float64, local_from_camera's first three rows at S evenly spaced times over the shutter "
     "(motion blur); shutter_table: None (a box shutter) or (K,) float32, the shutter curve's inverse CDF; "
     "rolling_shutter_duration: Cycles' rolling shutter (top to bottom) with that duration in [0, 1], "
     "negative (default): off. world_map: None "
     "(the uniform `world`) or (light, camera): equirectangular float32 (h, w, 3) radiance images of the world, "
     "the second (or None: the first) seen by camera rays; the first is sampled as a light. aov: None or (buffer "
     "float32 (h, w, channels), layout int32 (keys, 2) of [first channel or -1, width 1 or 4], alpha threshold): "
     "the view layer's shader AOVs."},
    {nullptr, nullptr, 0, nullptr},
};

PyGetSetDef RenderScene_getset[] = {
    {"instances", RenderScene_instances, nullptr, "Number of instances.", nullptr},
    {nullptr, nullptr, nullptr, nullptr, nullptr},
};

PyType_Slot RenderScene_slots[] = {
    {Py_tp_new, reinterpret_cast<void *>(RenderScene_new)},
    {Py_tp_dealloc, reinterpret_cast<void *>(RenderScene_dealloc)},
    {Py_tp_methods, RenderScene_methods},
    {Py_tp_getset, RenderScene_getset},
    {Py_tp_doc, const_cast<char *>("RenderScene(geometries, geometry_index, to_world, to_object, material_range, "
                                   "visibility, holdout, pass_index, materials, lights, threads=0, shadow_catcher=None, "
                                   "motion=None, motion_range=None, programs=None, object_values=None)\n\nmotion: (M, 12) float64 to_world rows of "
                                   "the moving instances at evenly spaced times over the shutter; motion_range: "
                                   "(n, 2) int32 each instance's (first row, count), count 0 when it does not move; "
                                   "programs: per material its node program (render/nodes.py Program.native()) or None; "
                                   "object_values: (n, k) float32, each instance's Object Info and object attributes "
                                   "(render/nodes.py OBJECT_INFO), k <= 73.")},
    {0, nullptr},
};

PyType_Spec RenderScene_spec = {"splat_tracer._core.RenderScene", sizeof(RenderSceneObject), 0, Py_TPFLAGS_DEFAULT,
                                RenderScene_slots};

}  // namespace

int add_render_types(PyObject *module) {
    PyObject *mesh = PyType_FromSpec(&Mesh_spec);
    if (!mesh) return -1;
    if (PyModule_AddObject(module, "Mesh", mesh) < 0) {
        Py_DECREF(mesh);
        return -1;
    }
    PyObject *rs = PyType_FromSpec(&RenderScene_spec);
    if (!rs) return -1;
    if (PyModule_AddObject(module, "RenderScene", rs) < 0) {
        Py_DECREF(rs);
        return -1;
    }
    static PyMethodDef run_nodes_def = {
        "run_nodes", run_nodes, METH_VARARGS,
        "run_nodes(code, data, outputs, images, globals, out[, attributes]): a node program run at each row of globals; out receives "
        "the registers (render/nodes.py)."};
    PyObject *fn = PyCFunction_NewEx(&run_nodes_def, nullptr, nullptr);
    if (!fn || PyModule_AddObject(module, "run_nodes", fn) < 0) {
        Py_XDECREF(fn);
        return -1;
    }
    return 0;
}

}  // namespace splat::py
