"""Fuzz harness: the native core's entry points, called directly (splat_tracer._core).

    python fuzz/fuzz_core.py [libFuzzer options] [corpus dirs]    (`make fuzz` runs it)

The input bytes are decoded (atheris.FuzzedDataProvider) into float32 splat arrays mixing
ordinary values with NaN, inf, -0.0, denormals, 1e18..1e19 and float32's extremes
(sometimes with a wrong dtype or shape), and then into calls of every native entry
point on them: _core.SplatCloud(...), trace, trace_surface (methods read by field name, exclude ids, inside
flags, tmin/tmax), render (camera matrices, windows, tile sizes), bvh_stats and bounds,
coherent rays (fans and parallel bundles) traced in packets and one by one, which must
agree exactly; then a _core.Mesh and a _core.RenderScene over both with fuzzed transforms, material
and lamp rows and settings, rendered; then the neighbour-graph functions (spatial_order,
permute_table, take_rows, graph_weights, spanning_forest, forest_traversal, chain_flips)
on fuzzed tables whose indices stray out of range, weights, anchors and orders, and
first_of_duplicates on the points (checked against a pairwise comparison); then a
_core.PointIndex and its queries (knn, knn_at, covering, radii, widest_gaps, pca) on fuzzed points,
rows, k, normals and spacings. The contract of a native entry point: it returns,
or raises ValueError, TypeError or MemoryError. Anything else (another exception, a
crash, and under the sanitizer build of `make fuzz` any AddressSanitizer or UBSan
report) is a finding.

`make fuzz` runs this harness against the ASan + UBSan build (build/sanitize/tree): the
native code is not coverage-instrumented (GCC cannot emit libFuzzer's coverage), so
atheris's guidance comes from the Python side and the decoding; the sanitizers turn
silent memory errors and undefined behaviour into findings.
Seed corpus: fuzz/corpus/core/.
"""
import dataclasses
import sys
from pathlib import Path
from types import SimpleNamespace

import atheris
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from splat_tracer import _core  # noqa: E402
from splat_tracer.render import cryptomatte, shading  # noqa: E402
from splat_tracer.render.camera import PROJECTIONS, Camera, Lens, Panorama  # noqa: E402
from splat_tracer.render.scene import RAY_VISIBILITY, InstanceRow, native_scene, render_arguments  # noqa: E402
from splat_tracer.render.shading import (PASSES, SETTINGS_FIELDS, Light, Material, RenderSettings,  # noqa: E402
                                         World)

# A clean refusal: the core's ValueError (InputError), a wrong type, no memory, or CPython's
# argument parsing refusing an integer beyond its C type (OverflowError: a fuzzed
# adaptive_min_samples of 4.6e14 for an int, found by the fuzzer) -- never a crash.
ALLOWED = (ValueError, TypeError, MemoryError, OverflowError)
SPECIAL = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1e-45, 1.1754942e-38, 1e18, -1e18, 1.0000001e18, 1e19, -1e19,
           3.4028235e38, -3.4028235e38, 1.0, -1.0, 0.5, 2.0, 1e-7, 1e7]
MAX_LAYER_HITS = _core.MAX_LAYER_HITS


@atheris.instrument_func  # Python-side coverage: which branches and refusals an input reached
def value(fdp) -> float:
    k = fdp.ConsumeIntInRange(0, 3)
    if k == 0:
        return SPECIAL[fdp.ConsumeIntInRange(0, len(SPECIAL) - 1)]
    if k == 1:
        return fdp.ConsumeFloat()  # any double, NaN and inf included
    return fdp.ConsumeFloatInRange(-3.0, 3.0)  # mostly ordinary geometry


@atheris.instrument_func
def array(fdp, shape, dtype=np.float32, sane: bool = False):
    """Fuzzed values (value()) of shape, now and then of a wrong dtype or layout; sane: plain
    geometry in -3..3 of the right layout (so that, most times, the core accepts the object
    and the calls on it run past their checks)."""
    n = int(np.prod(shape))
    if sane:
        return np.array([fdp.ConsumeFloatInRange(-3.0, 3.0) for _ in range(n)], dtype).reshape(shape)
    a = np.array([value(fdp) for _ in range(n)], np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        out = a.astype(dtype).reshape(shape)
    if fdp.ConsumeIntInRange(0, 30) == 0:  # now and then a wrong dtype or layout
        out = [out.astype(np.float64), out.T, out.ravel(), "not an array", None][fdp.ConsumeIntInRange(0, 4)]
    return out


@atheris.instrument_func
def method(fdp):
    """A method object as the core reads it (by field name), its fields fuzzed past what
    render.method.Method would accept; now and then not a method at all or one missing a field."""
    if fdp.ConsumeIntInRange(0, 20) == 0:
        return [None, "FULL", (True, True, True, 1, 0, 1.0), SimpleNamespace(far_phase=True),
                SimpleNamespace(**{**FULL, "epsilon": "1"})][fdp.ConsumeIntInRange(0, 4)]
    positions = ("FIRST", "NEAR_PHASE", "NEAREST_CENTRE", "MIDDLE", 1)  # the last two: refused
    kernels = ("LINEAR", "SMOOTH", "", None)
    wild = fdp.ConsumeIntInRange(0, 3) == 0  # else one the core accepts, so that what follows runs
    return SimpleNamespace(wrong_hit_elimination=fdp.ConsumeBool(), normal_interpolation=fdp.ConsumeBool(),
                           far_phase=fdp.ConsumeBool(), position=positions[fdp.ConsumeIntInRange(0, 4 if wild else 2)],
                           kernel=kernels[fdp.ConsumeIntInRange(0, 3 if wild else 1)],
                           epsilon=value(fdp) if wild else fdp.ConsumeFloatInRange(0.0, 3.0),
                           crease_angle=[180.0, 45.0, value(fdp)][fdp.ConsumeIntInRange(0, 2 if wild else 1)])


FULL = dict(wrong_hit_elimination=True, normal_interpolation=True, far_phase=True, position="NEAR_PHASE",
            kernel="LINEAR", epsilon=1.0, crease_angle=180.0)


def small_int(fdp):
    return [0, 1, 2, 3, 7, 8, 16, 33, -1, 2**31 - 1, -2**31][fdp.ConsumeIntInRange(0, 10)]


@atheris.instrument_func
def call(fn, *args, **kwargs):
    try:
        return fn(*args, **kwargs)
    except ALLOWED:
        return None


@atheris.instrument_func
def camera(fdp):
    if fdp.ConsumeBool():  # a plausible camera looking at the origin, from a fuzzed place
        m = np.eye(4)
        m[:3, :3] *= fdp.ConsumeFloatInRange(0.1, 3)
        m[:3, 3] = [value(fdp) for _ in range(3)]
        m[3, 2] = fdp.ConsumeFloatInRange(-1, 1)
        m[3, 3] = fdp.ConsumeFloatInRange(0, 2)
    else:
        m = np.array([value(fdp) for _ in range(16)], np.float64).reshape(4, 4)
    pos = np.array([value(fdp) for _ in range(3)], np.float64)
    fwd = np.array([value(fdp) for _ in range(3)], np.float64)
    return np.ascontiguousarray(m), pos, fwd


@atheris.instrument_func
def fuzz_scene(fdp):
    n = fdp.ConsumeIntInRange(0, 40)
    sane = fdp.ConsumeBool()  # a cloud the core accepts, or (mostly) one it refuses
    c, nrm = array(fdp, (n, 3), sane=sane), array(fdp, (n, 3), sane=sane)
    r = array(fdp, (n,), sane=sane)
    if sane:
        r = np.abs(r) + np.float32(0.01)
    col = array(fdp, (n, 3), sane=sane) if fdp.ConsumeBool() else None
    closed = np.frombuffer(fdp.ConsumeBytes(n).ljust(n, b"\1"), np.uint8).copy() if fdp.ConsumeBool() else None
    scene = call(_core.SplatCloud, c, nrm, r, col, closed, fdp.ConsumeIntInRange(0, 3))
    if scene is None:
        return None
    assert scene.size == n
    scene.bvh_stats()
    b = scene.bounds
    assert (b is None) == (n == 0)

    k = fdp.ConsumeIntInRange(0, 24)
    o, d = array(fdp, (k, 3)), array(fdp, (k, 3))
    tmin, tmax = value(fdp), value(fdp)
    out = (np.empty(k, np.float32), np.empty(k, np.int32), np.empty(k, np.uint8))
    if call(scene.trace, o, d, tmin, tmax, *out, np.empty((k, 3), np.float32), fdp.ConsumeIntInRange(0, 3),
            fdp.ConsumeBool(), np.zeros(2, np.int64)) is not None:
        t, ids, _ = out
        assert ((ids >= -1) & (ids < n)).all()
        assert (np.isinf(t) == (ids < 0)).all()
    m_ex = fdp.ConsumeIntInRange(0, 4)
    ex = np.array([fdp.ConsumeIntInRange(-2, n) for _ in range(k * m_ex)], np.int32).reshape(k, m_ex)
    inside = np.frombuffer(fdp.ConsumeBytes(k).ljust(k, b"\0"), np.uint8).copy()
    sout = (np.empty(k, np.float32), np.empty(k, np.int32), np.empty(k, np.uint8), np.empty((k, 3), np.float32),
            np.empty((k, 3), np.float32), np.empty((k, MAX_LAYER_HITS), np.int32))
    if call(scene.trace_surface, o, d, tmin, tmax, method(fdp), *sout, inside if fdp.ConsumeBool() else None,
            ex if fdp.ConsumeBool() else None, fdp.ConsumeIntInRange(0, 3), fdp.ConsumeBool()) is not None:
        assert ((sout[1] >= -1) & (sout[1] < n)).all() and ((sout[5] >= -1) & (sout[5] < n)).all()

    width, height = fdp.ConsumeIntInRange(1, 24), fdp.ConsumeIntInRange(1, 24)
    win = (0, 0, width, height) if fdp.ConsumeBool() else tuple(small_int(fdp) for _ in range(4))
    h, w = max(win[3], 0), max(win[2], 0)
    if h * w <= 4096:
        cam = scene_camera(fdp)  # its lens is ignored: the cloud's render is a pinhole's
        call(scene.render, *cam.native(), width, height, win, (value(fdp), 0.0, 0.0, 1.0),
             np.empty((h, w, 4), np.float32), np.empty((h, w), np.float32), np.empty((h, w, 3), np.float32),
             fdp.ConsumeIntInRange(0, 3), None, small_int(fdp), method(fdp))
    fuzz_packets(fdp, scene, n)
    return scene


def fuzz_packets(fdp, scene, n):
    """Coherent rays (a fuzzed origin and direction, spread by a fuzzed angle or, parallel,
    over a fuzzed patch of origins): packets must give exactly the answers of single rays."""
    k = fdp.ConsumeIntInRange(1, 40)
    def vectors(count):  # well-formed arrays (array() may give wrong shapes or dtypes on purpose)
        return np.array([[value(fdp) for _ in range(3)] for _ in range(count)], np.float32).reshape(count, 3)
    o0, d0 = vectors(1), vectors(1)
    spread = (0.0, 1e-7, 1e-4, 0.01, 0.1)[fdp.ConsumeIntInRange(0, 4)]
    offsets = vectors(k) * np.float32(spread) if fdp.ConsumeBool() else np.zeros((k, 3), np.float32)
    with np.errstate(all="ignore"):
        i = np.arange(k)
        jitter = np.column_stack([i % 4, i // 4 % 4, np.zeros(k)]).astype(np.float32) * np.float32(spread)
        if fdp.ConsumeBool():
            o, d = np.repeat(o0, k, 0), (d0 + jitter + offsets).astype(np.float32)  # a fan from one point
        else:
            o, d = (o0 + jitter + offsets).astype(np.float32), np.repeat(d0, k, 0)  # parallel rays
    tmin, tmax = value(fdp), value(fdp)
    meth = method(fdp)
    outs = []
    for packets in (True, False):
        out = (np.empty(k, np.float32), np.empty(k, np.int32), np.empty(k, np.uint8))
        sout = (np.empty(k, np.float32), np.empty(k, np.int32), np.empty(k, np.uint8),
                np.empty((k, 3), np.float32), np.empty((k, 3), np.float32), np.empty((k, MAX_LAYER_HITS), np.int32))
        a = call(scene.trace, o, d, tmin, tmax, *out, None, 1, False, None, packets)
        b = call(scene.trace_surface, o, d, tmin, tmax, meth, *sout, None, None, 1, False, packets)
        outs.append((a is not None, out, b is not None, sout))
    (a1, out1, b1, s1), (a2, out2, b2, s2) = outs
    assert a1 == a2 and b1 == b2
    if a1:
        for x, y in zip(out1, out2):
            assert np.array_equal(x, y), "packets changed a nearest hit"
    if b1:
        for x, y in zip(s1, s2):
            assert np.array_equal(x, y, equal_nan=True), "packets changed a surface"


# Which packed fields a fuzzed object picks from an enumeration (other strings keep their default).
ENUMS = {"type": shading.LIGHT_TYPES, "shape": shading.AREA_SHAPES, "emission_sampling": shading.EMISSION_SAMPLING,
         "pixel_filter": shading.PIXEL_FILTERS, "mesh_light_strategy": shading.MESH_LIGHT_STRATEGIES}
# Counts now and then: in range, at the core's limits, just past them and extreme (int32
# only: a wider int is refused by Python's argument parsing as OverflowError, not by the core).
COUNTS = [0, 1, 2, 3, 7, 33, 1024, 1025, 65536, 65537, -1, 2**31 - 1, -2**31]
# Work one render may do before the harness gives it a time limit (a fuzz input must stay
# fast): camera samples x shadow samples x AO samples. One round of the time-limited render
# is one sample, so shadow x AO samples are capped at MAX_RAYS_PER_SAMPLE on their own.
WORK_BUDGET = 64
MAX_RAYS_PER_SAMPLE = 64
TINY_TIME_LIMIT = 0.002  # seconds: the render stops after its first one-sample round


@atheris.instrument_func
def plausible(fdp, default):
    """A value of default's kind (bool, int, float, a sequence of them, a set of names, an
    enumeration name), mostly one the add-on's checks accept (so scenes do render)."""
    if isinstance(default, (bool, np.bool_)):
        return fdp.ConsumeBool()
    if isinstance(default, (int, np.integer)):
        return fdp.ConsumeIntInRange(min(int(default), 1), max(4, 2 * int(default)))  # counts of 1+ stay 1+
    if isinstance(default, (float, np.floating)):
        return fdp.ConsumeFloatInRange(min(0.0, 2 * float(default)), max(1.0, 2 * float(default)))
    if isinstance(default, frozenset):
        return frozenset(k for k in sorted(default) if fdp.ConsumeBool())
    if isinstance(default, (tuple, list, np.ndarray)):
        return type(default)(plausible(fdp, v) for v in default) if not isinstance(default, np.ndarray) else \
            np.array([plausible(fdp, v) for v in default.ravel()], default.dtype).reshape(default.shape)
    return default


@atheris.instrument_func
def hostile(fdp, default):
    """A value of default's kind that the add-on would refuse or never produce: NaN, inf,
    negative, huge (value()), counts out of range (COUNTS)."""
    if isinstance(default, (bool, np.bool_)):
        return fdp.ConsumeBool()
    if isinstance(default, (int, np.integer)):
        return COUNTS[fdp.ConsumeIntInRange(0, len(COUNTS) - 1)]
    if isinstance(default, (float, np.floating)):
        return value(fdp)
    if isinstance(default, (tuple, list)):
        return type(default)(hostile(fdp, v) if fdp.ConsumeBool() else v for v in default)
    if isinstance(default, np.ndarray):
        out = default.copy()
        flat = out.reshape(-1)
        for i in range(flat.size):
            if fdp.ConsumeBool():
                with np.errstate(over="ignore", invalid="ignore"):
                    flat[i] = hostile(fdp, flat[i].item())
        return out
    return default


def corrupt(fdp, entries, odds: int = 6):
    """entries (a packed row, a settings tuple, a NamedTuple row), one time in `odds` with
    entries made hostile (each one time in four), keeping their kinds. Rare, as one hostile
    entry makes the core refuse the whole scene."""
    if fdp.ConsumeIntInRange(0, odds - 1):
        return entries
    out = [hostile(fdp, v) if fdp.ConsumeIntInRange(0, 3) == 0 else v for v in entries]
    if isinstance(entries, np.ndarray):
        with np.errstate(over="ignore", invalid="ignore"):
            return np.array(out, np.float64).astype(entries.dtype)
    return type(entries)(*out) if hasattr(entries, "_fields") else type(entries)(out)


@atheris.instrument_func
def unchecked(fdp, cls):
    """An instance of the add-on's dataclass cls (Light, Material, RenderSettings, World,
    Lens) with every field fuzzed by its default's kind and never validated (its checks
    are bypassed): plausible mostly, all hostile one time in eight. Its pack() or native()
    gives the row the add-on would give the core, whatever fields the class has now."""
    wild = fdp.ConsumeIntInRange(0, 7) == 0
    obj = object.__new__(cls)
    for f in dataclasses.fields(cls):
        default = f.default if f.default is not dataclasses.MISSING else 1.0  # Lens's radius, focus_distance
        if f.name in ENUMS:
            v = ENUMS[f.name][fdp.ConsumeIntInRange(0, len(ENUMS[f.name]) - 1)]
        else:
            v = hostile(fdp, default) if wild else plausible(fdp, default)
        object.__setattr__(obj, f.name, v)
    return obj


def packed(make, fallback):
    """make() (a pack() of an unchecked object), or fallback when the add-on's own packing
    fails on the unchecked values (a zero-sample threshold divides by 0): the core never sees those."""
    try:
        with np.errstate(all="ignore"):
            return make()
    except (ValueError, ZeroDivisionError, OverflowError):
        return fallback


@atheris.instrument_func
def fuzz_settings(fdp):
    """RenderSettings.pack() of fuzzed settings, entries made hostile, bounded in work: every
    field the add-on packs (clamps, filter glossy, adaptive sampling, the time limit, the
    mesh-light strategy...) is fuzzed, by its name in SETTINGS_FIELDS."""
    s = dict(zip(SETTINGS_FIELDS, corrupt(fdp, packed(unchecked(fdp, RenderSettings).pack,
                                                      RenderSettings(samples=1).pack()))))
    counts = [s[k] for k in ("samples", "shadow_samples", "ao_samples")]
    if all(isinstance(c, int) for c in counts):
        if max(counts[1], 1) * max(counts[2], 1) > MAX_RAYS_PER_SAMPLE:
            s["ao_samples"] = 1 if counts[1] <= 1024 else s["ao_samples"]
            s["shadow_samples"] = min(s["shadow_samples"], MAX_RAYS_PER_SAMPLE) if s["shadow_samples"] <= 1024 \
                else s["shadow_samples"]
        if max(counts[0], 1) * max(s["shadow_samples"], 1) * max(s["ao_samples"], 1) > WORK_BUDGET and \
                not (isinstance(s["time_limit"], float) and 0 < s["time_limit"] <= TINY_TIME_LIMIT):
            s["time_limit"] = TINY_TIME_LIMIT
    assert len(s) == len(SETTINGS_FIELDS)
    return tuple(s[k] for k in SETTINGS_FIELDS)


@atheris.instrument_func
def scene_camera(fdp):
    """A Camera (unchecked): mostly Camera.look_at from a fuzzed eye, or any matrix,
    frustum and clip; a thin lens (depth of field) and a panorama (unchecked parameters) now
    and then."""
    cam = None
    if fdp.ConsumeIntInRange(0, 3):
        eye = [fdp.ConsumeFloatInRange(-6, 6) for _ in range(3)]
        try:
            cam = Camera.look_at(eye, (0.0, 0.0, 0.0), fov_y=fdp.ConsumeFloatInRange(1, 170),
                                 ortho_height=fdp.ConsumeFloatInRange(0.1, 5) if fdp.ConsumeBool() else None)
        except ValueError:  # an eye at the target
            cam = None
    if cam is None:
        m, _, _ = camera(fdp)
        cam = object.__new__(Camera)
        for name, v in (("local_from_camera", m), ("frustum", tuple(value(fdp) for _ in range(4))),
                        ("clip", tuple(value(fdp) for _ in range(2))), ("orthographic", fdp.ConsumeBool()),
                        ("lens", None), ("panorama", None)):
            object.__setattr__(cam, name, v)
    if fdp.ConsumeIntInRange(0, 2) == 0:
        lens = unchecked(fdp, Lens)
        object.__setattr__(lens, "blades", fdp.ConsumeIntInRange(-1, 9))
        copy = object.__new__(Camera)  # a copy with the lens, without Camera's checks
        copy.__dict__.update(cam.__dict__, lens=lens)
        cam = copy
    if fdp.ConsumeIntInRange(0, 2) == 0:
        panorama = object.__new__(Panorama)  # any of the kinds, its parameters unchecked
        object.__setattr__(panorama, "kind", PROJECTIONS[fdp.ConsumeIntInRange(1, len(PROJECTIONS) - 1)])
        object.__setattr__(panorama, "parameters", tuple(value(fdp) for _ in range(fdp.ConsumeIntInRange(0, 5))))
        copy = object.__new__(Camera)
        copy.__dict__.update(cam.__dict__, panorama=panorama)
        cam = copy
    return cam


@atheris.instrument_func
def instance_row(fdp, n_geo, n_mat):
    """A scene.InstanceRow: mostly a placed, invertible transform and a material range inside
    the materials; then its columns made hostile now and then."""
    m = np.eye(4)
    if fdp.ConsumeBool():
        m[:3, :3] *= fdp.ConsumeFloatInRange(0.2, 3)
        m[:3, 3] = [fdp.ConsumeFloatInRange(-2, 2) for _ in range(3)]
    with np.errstate(all="ignore"):
        inv = np.linalg.inv(m)
    first = fdp.ConsumeIntInRange(0, max(n_mat - 1, 0))
    row = InstanceRow(geometry_index=fdp.ConsumeIntInRange(0, max(n_geo - 1, 0)), to_world=m[:3].ravel(),
                      to_object=inv[:3].ravel(), material_range=(first, fdp.ConsumeIntInRange(1, max(n_mat - first, 1))),
                      visibility=sum(v for v in RAY_VISIBILITY.values() if fdp.ConsumeIntInRange(0, 5)),
                      holdout=fdp.ConsumeIntInRange(0, 7) == 0, pass_index=fdp.ConsumeIntInRange(0, 9),
                      shadow_catcher=fdp.ConsumeIntInRange(0, 5) == 0,
                      # Now and then it moves: the frame's transform, then a shifted one.
                      motion=(np.stack([m[:3].ravel(), (m[:3] + [[0, 0, 0, fdp.ConsumeFloatInRange(-2, 2)]] * 3).ravel()])
                              if fdp.ConsumeIntInRange(0, 3) == 0 else None))
    return corrupt(fdp, row)


@atheris.instrument_func
def fuzz_render_scene(fdp, splats):
    """A _core.RenderScene over the fuzzed cloud and a fuzzed mesh, built and rendered with the
    add-on's own layouts (scene.native_scene, scene.render_arguments, Material/Light/
    RenderSettings.pack()) from unchecked objects whose values are made hostile. Returns
    the render's counters (and the scene's lights and instances) when the core accepted the
    scene and rendered, else None."""
    v = fdp.ConsumeIntInRange(0, 12)
    sane = fdp.ConsumeIntInRange(0, 3) > 0  # mostly a mesh the core accepts: the scene is the point here
    verts = array(fdp, (v, 3), sane=sane)
    lo, hi = (0, v - 1) if sane else (-1, v)
    tris = np.array([fdp.ConsumeIntInRange(lo, hi) for _ in range(3 * fdp.ConsumeIntInRange(0, 6) * (hi >= lo))],
                    np.int32).reshape(-1, 3)
    t = len(tris)
    normals = array(fdp, (t, 3, 3)) if fdp.ConsumeBool() else None
    mat_index = np.array([fdp.ConsumeIntInRange(-1, 3) for _ in range(t)], np.int32) if fdp.ConsumeBool() else None
    mesh = call(_core.Mesh, verts, tris, normals, mat_index, 1)
    geos = [g for g in (splats, mesh) if g is not None]
    if not geos:
        return None
    n_mat = fdp.ConsumeIntInRange(1, 3) if fdp.ConsumeIntInRange(0, 7) else 0  # 0: every instance refused
    n_light = fdp.ConsumeIntInRange(0, 3)
    materials = [corrupt(fdp, packed(unchecked(fdp, Material).pack, Material().pack())) for _ in range(n_mat)]
    lights = [corrupt(fdp, packed(unchecked(fdp, Light).pack, Light().pack())) for _ in range(n_light)]
    rows = [instance_row(fdp, len(geos), n_mat) for _ in range(fdp.ConsumeIntInRange(0, 4))]
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # hostile doubles cast to float32
            scene = call(native_scene, geos, rows, materials, lights, fdp.ConsumeIntInRange(0, 2))
    except OverflowError:  # numpy refusing a hostile count as int32/uint8, before the core
        return None
    if scene is None:
        return None
    call(scene.mesh_lights)
    w, h = fdp.ConsumeIntInRange(1, 12), fdp.ConsumeIntInRange(1, 12)
    passes = [name for name in PASSES if fdp.ConsumeBool()]
    ids = None
    if fdp.ConsumeIntInRange(0, 3) == 0:  # Cryptomatte: ids from sane names, or fuzzed values and layouts
        passes += [kind for kind in cryptomatte.KINDS if fdp.ConsumeBool()] or ["CryptoObject"]
        sane = fdp.ConsumeIntInRange(0, 3) > 0
        make = (lambda shape: np.array([cryptomatte.name_id(str(fdp.ConsumeIntInRange(0, 9)))
                                        for _ in range(int(np.prod(shape)))], np.float32).reshape(shape)) \
            if sane else (lambda shape: array(fdp, shape))
        ids = (make((scene.instances, 2)), make((max(n_mat, 1),)))
    kwargs, _ = render_arguments(scene_camera(fdp), w, h, RenderSettings(), method(fdp), unchecked(fdp, World),
                                 passes, cryptomatte_ids=ids, cryptomatte_levels=fdp.ConsumeIntInRange(0, 17))
    kwargs["settings"] = fuzz_settings(fdp)
    for name in ("world", "film_transparent", "world_visibility", "lens", "frustum"):
        if kwargs[name] is not None and fdp.ConsumeIntInRange(0, 7) == 0:
            kwargs[name] = hostile(fdp, kwargs[name])
    got = call(scene.render, **kwargs, threads=fdp.ConsumeIntInRange(0, 2), tile_size=fdp.ConsumeIntInRange(1, 8),
               packets=fdp.ConsumeBool())
    if got is None:
        return None
    done, counters = got
    assert done and counters["samples_reached"] >= 1, counters
    return dict(counters, lights=len(lights), instances=len(rows))


@atheris.instrument_func
def indices(fdp, shape, n):
    """int32 indices, mostly in 0..n-1, now and then just outside or extreme."""
    count = int(np.prod(shape))
    out = np.array([fdp.ConsumeIntInRange(0, max(n - 1, 0)) if fdp.ConsumeIntInRange(0, 15) else small_int(fdp)
                    for _ in range(count)], np.int64)
    return out.astype(np.int32).reshape(shape)


@atheris.instrument_func
def fuzz_graph(fdp):
    n, k = fdp.ConsumeIntInRange(0, 30), fdp.ConsumeIntInRange(0, 5)
    pts, nrm = array(fdp, (n, 3), np.float64), array(fdp, (n, 3), np.float64)
    nbr = indices(fdp, (n, k), n)
    threads = fdp.ConsumeIntInRange(0, 3)
    order = np.empty(n, np.int32)
    if call(lambda: _core.spatial_order(pts, order, threads) or True):  # None: refused (it returns None on success)
        assert sorted(order) == list(range(n))
    else:
        order = indices(fdp, (n,), n)
    first = np.empty(n, bool)
    if call(lambda: _core.first_of_duplicates(pts, first, threads) or True):  # None: refused
        for i in range(n):  # equal as numbers: -0.0 is 0.0, a row with a NaN equals none
            assert first[i] == (not (pts[:i] == pts[i]).all(axis=1).any()), i
    call(_core.permute_table, nbr, order, fdp.ConsumeIntInRange(-1, k), np.empty((n, fdp.ConsumeIntInRange(0, k)),
                                                                                  np.int32), threads)
    rows = indices(fdp, (fdp.ConsumeIntInRange(0, 10),), n)
    call(_core.take_rows, pts, rows, np.empty((len(rows), 3)), threads)
    weights = np.empty((n, k), np.float32)
    if call(_core.graph_weights, pts, nrm, nbr, value(fdp), weights, threads) is None:
        weights = array(fdp, (n, k))
    edges, labels = np.empty((max(n - 1, 0), 2), np.int32), np.empty(n, np.int32)
    got = call(_core.spanning_forest, nbr, weights, edges, labels, threads)
    if got is not None:
        m, components = got
        assert m + components == n and ((labels >= 0) & (labels < max(components, 1))).all()
        edges = edges[:m]
    else:
        edges = indices(fdp, (fdp.ConsumeIntInRange(0, 8), 2), n)
    anchors = np.frombuffer(fdp.ConsumeBytes(n).ljust(n, b"\0"), np.uint8).copy()
    parent, visit = np.empty(n, np.int32), np.empty(n, np.int32)
    reached = call(_core.forest_traversal, edges, anchors, parent, visit)
    if reached is None:
        parent, visit, reached = indices(fdp, (n,), n), indices(fdp, (n,), n), n
    flip = np.frombuffer(fdp.ConsumeBytes(n).ljust(n, b"\0"), np.uint8).copy()
    call(_core.chain_flips, visit[:reached], parent, flip, np.empty(n, np.uint8))


@atheris.instrument_func
def fuzz_neighbours(fdp):
    """_core.PointIndex over fuzzed points (coincident ones often), and every query on fuzzed
    rows, k, normals, spacings and outputs."""
    n = fdp.ConsumeIntInRange(0, 40)
    pts = array(fdp, (n, 3))
    if fdp.ConsumeIntInRange(0, 3) == 0 and isinstance(pts, np.ndarray) and pts.ndim == 2 and len(pts) > 1:
        pts[fdp.ConsumeIntInRange(0, len(pts) - 1):] = pts[0]  # a pile of coincident points
    index = call(_core.PointIndex, pts, fdp.ConsumeIntInRange(0, 3))
    if index is None:
        return
    size = index.size
    order = np.empty(size, np.int32)
    index.order(order)
    assert sorted(order) == list(range(size))
    m = fdp.ConsumeIntInRange(0, 12)
    start = fdp.ConsumeIntInRange(0, size)
    pick = fdp.ConsumeIntInRange(0, 2)  # a run of the order, runs of it (a sampled boundary test), or anything
    if pick == 0:
        rows = order[start:start + m]
    elif pick == 1:
        other = fdp.ConsumeIntInRange(0, size)
        rows = np.concatenate([order[start:start + m], order[other:other + fdp.ConsumeIntInRange(0, 12)]])
    else:
        rows = indices(fdp, (m,), size)
    k, threads = small_int(fdp) if fdp.ConsumeIntInRange(0, 7) == 0 else fdp.ConsumeIntInRange(1, 13), \
        fdp.ConsumeIntInRange(0, 3)
    cols = min(max(k, 0), 300)  # outputs sized for k, but never gigabytes (the core refuses k > 256 anyway)
    shape = (len(rows), cols)
    call(index.knn, rows, k, np.empty(shape, np.float32), np.empty(shape, np.int32), threads)
    call(index.radii, rows, k, np.empty(len(rows), np.float32), threads=threads)
    q = array(fdp, (fdp.ConsumeIntInRange(0, 5), 3))
    rq = len(q) if isinstance(q, np.ndarray) and q.ndim == 2 else 0
    call(index.knn_at, q, k, np.empty((rq, cols), np.float32), np.empty((rq, cols), np.int32), threads)
    normals, spacing = array(fdp, (size, 3)), array(fdp, (size,))
    hole, gap = value(fdp), value(fdp)
    call(index.covering, rows, normals, spacing, k, hole, gap, np.empty(len(rows), np.float32), threads)
    call(index.widest_gaps, rows, k, normals, np.empty(len(rows), np.float32), threads)
    call(index.radii, rows, fdp.ConsumeIntInRange(0, 8), np.empty(len(rows), np.float32), normals, k, hole, gap,
         np.empty(len(rows), np.float32), threads)
    width = fdp.ConsumeIntInRange(0, 14)
    call(index.pca, rows, k, np.empty((len(rows), 3)), np.empty((len(rows), width), np.int32) if width else None,
         fdp.ConsumeIntInRange(0, 8), np.empty(len(rows), np.float32), fdp.ConsumeIntInRange(0, 14), hole, gap,
         np.empty(len(rows), np.float32), threads)


@atheris.instrument_func
def TestOneInput(data: bytes) -> None:
    fdp = atheris.FuzzedDataProvider(data)
    splats = fuzz_scene(fdp)
    fuzz_render_scene(fdp, splats)
    fuzz_graph(fdp)
    fuzz_neighbours(fdp)


if __name__ == "__main__":
    atheris.Setup(sys.argv, TestOneInput)
    atheris.Fuzz()
