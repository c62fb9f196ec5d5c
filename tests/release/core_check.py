"""Run by path in each Python under test (test_windows.py): the same calls into a core on
the same inputs, the answers written to an .npz for the caller to compare.

    python core_check.py TREE INPUTS.npz OUTPUT.npz

TREE holds a copy of the splat_tracer package with the core under test (the Linux or the
Windows build); it goes first on sys.path, so that no other build can be imported. Prints
one JSON line of facts: where the module came from, its SIMD path, the Python.

Two parts. The core's own entry points (`_core.SplatCloud`, `PointIndex`) take any buffer, so
they are called with memoryviews and the .npz is read and written by hand (an .npy is a
short header and the raw array): that part needs no numpy, and runs in Windows Python 3.13
under Wine 8.0, where numpy 2's Windows wheels do not load (they need ucrtbase's crealf,
which Wine 8.0 lacks). Where numpy is present, the Python API over the core runs too:
a RenderScene lit by a sun over a mesh floor, `trace_surface`, the normals' estimation and
orientation and the splat radii, as the importer calls them. Input arrays come from the
caller's numpy, never computed here: both sides see the same bits.
"""
import ast
import json
import sys
import zipfile

tree, inputs_path, output_path = sys.argv[1:4]
sys.path.insert(0, tree)

from splat_tracer import _core  # noqa: E402

THREADS = 2  # the answers do not depend on it (tests/render); fixed so that both sides do the same work
NPY_MAGIC = b"\x93NUMPY"
# .npy dtype strings <-> struct formats of memoryview.cast, for the arrays used here.
FORMATS = {"<f4": "f", "<f8": "d", "<i4": "i", "|u1": "B", "|b1": "?"}
DESCRS = {fmt: descr for descr, fmt in FORMATS.items()}


def read_npz(path) -> dict:
    arrays = {}
    with zipfile.ZipFile(path) as z:
        for name in z.namelist():
            raw = z.read(name)
            assert raw[:6] == NPY_MAGIC, name
            size_bytes = 2 if raw[6] == 1 else 4  # header length field: 2 bytes in format 1.0, 4 after
            start = 8 + size_bytes
            header_len = int.from_bytes(raw[8:start], "little")
            header = ast.literal_eval(raw[start:start + header_len].decode("latin1"))
            assert not header["fortran_order"] and header["descr"] in FORMATS, (name, header)
            data = memoryview(bytearray(raw[start + header_len:]))
            shape = list(header["shape"])
            arrays[name[:-4]] = data.cast(FORMATS[header["descr"]], shape) if shape else data.cast(
                FORMATS[header["descr"]])[0]
    return arrays


def npy_bytes(view: memoryview) -> bytes:
    # numpy's int32 is C long on Windows: format "l" there, "i" on Linux.
    fmt = "i" if view.format == "l" and view.itemsize == 4 else view.format
    header = repr({"descr": DESCRS[fmt], "fortran_order": False, "shape": tuple(view.shape)}).encode("latin1")
    header += b" " * (-(10 + len(header) + 1) % 64) + b"\n"  # the data starts 64-byte aligned, as numpy writes
    return NPY_MAGIC + bytes([1, 0]) + len(header).to_bytes(2, "little") + header + view.tobytes()


def empty(fmt: str, *shape: int) -> memoryview:
    count = 1
    for s in shape:
        count *= s
    return memoryview(bytearray(count * {"f": 4, "d": 8, "i": 4, "B": 1}[fmt])).cast(fmt, list(shape))


def core_part(i: dict) -> dict:
    """The compiled module's entry points, with memoryviews."""
    out = {}
    scene = _core.SplatCloud(i["centres"], i["normals"], i["radii"], None, None, THREADS)
    rays = i["origins"].shape[0]
    t, ids, front, normal = empty("f", rays), empty("i", rays), empty("B", rays), empty("f", rays, 3)
    scene.trace(i["origins"], i["directions"], 0.0, float("inf"), t, ids, front, normal, THREADS)
    out.update(trace_t=t, trace_id=ids, trace_front=front, trace_normal=normal)

    w, h = i["size"][0], i["size"][1]
    rgba, depth, normals = empty("f", h, w, 4), empty("f", h, w), empty("f", h, w, 3)
    scene.render(i["local_from_camera"], i["frustum"], bool(i["orthographic"][0]), w, h, (0, 0, w, h), (0.0, 0.0, 0.0, 0.0),
                 rgba, depth, normals, THREADS)  # the headlight, the default method
    out.update(headlight_rgba=rgba, headlight_depth=depth, headlight_normal=normals)

    index = _core.PointIndex(i["centres"], THREADS)
    k, queries = 8, i["queries"].shape[0]
    dist, nearest = empty("f", queries, k), empty("i", queries, k)
    index.knn_at(i["queries"], k, dist, nearest, THREADS)
    out.update(knn_at_dist=dist, knn_at_ids=nearest)
    rows = i["rows"]
    dist, nearest = empty("f", rows.shape[0], k), empty("i", rows.shape[0], k)
    index.knn(rows, k, dist, nearest, THREADS)
    out.update(knn_dist=dist, knn_ids=nearest)
    return out


def api_part(i: dict) -> dict:
    """The Python API over the core (numpy): what the importer and the renderer call."""
    import numpy as np

    from splat_tracer.pointcloud import normals as normals_mod
    from splat_tracer.pointcloud.neighbours import PointIndex
    from splat_tracer.render.camera import Camera
    from splat_tracer.render.method import Method
    from splat_tracer.render.scene import Instance, Mesh, RenderScene
    from splat_tracer.render.shading import Light, Material, RenderSettings
    from splat_tracer.render.splats import SplatCloud

    a = {name: np.asarray(value) for name, value in i.items()}
    out = {}
    cloud = SplatCloud(a["centres"], a["normals"], a["radii"], threads=THREADS)
    surface = cloud.trace_surface(a["origins"], a["directions"], Method(), members=True, threads=THREADS)
    out.update({f"surface_{name}": value for name, value in surface._asdict().items()})

    floor = Mesh(a["floor_vertices"], a["floor_triangles"], threads=THREADS)
    grey = Material(base_colour=(0.8, 0.8, 0.8), roughness=0.5)
    scene = RenderScene([Instance(cloud, materials=(grey,), pass_index=1), Instance(floor, pass_index=2)],
                        [Light(type="SUN", power=3.0, direction=tuple(a["sun_direction"]))], threads=THREADS)
    camera = Camera(a["local_from_camera"], tuple(a["frustum"][:4]), tuple(a["frustum"][4:6]),
                    bool(a["orthographic"][0]))
    w, h = (int(v) for v in a["size"])
    frame = scene.render(camera, w, h, RenderSettings(samples=4), passes=(
        "Combined", "Depth", "Normal", "DiffCol", "Shadow", "IndexOB"), threads=THREADS)
    out.update({f"scene_{name}": value for name, value in frame.passes.items()})

    orientation, spacing, cover = normals_mod.estimate_and_orient(a["centres"], radius_k=6, workers=THREADS,
                                                                  close_gaps=True)
    out.update(orient_normals=orientation.normals, orient_ambiguous=orientation.ambiguous, orient_spacing=spacing,
               orient_cover=cover)
    index = PointIndex(a["centres"], THREADS)
    radii = index.radii(np.arange(len(index), dtype=np.int32), 6, a["normals"], cover_k=12, hole=3.0, max_gap=2.0)
    out.update(radii_spacing=radii[0], radii_cover=radii[1])
    return {name: memoryview(np.ascontiguousarray(value)) for name, value in out.items()}


inputs = read_npz(inputs_path)
answers = core_part(inputs)
try:
    import numpy
except ImportError:
    numpy = None
if numpy is not None:
    answers.update(api_part(inputs))
with zipfile.ZipFile(output_path, "w") as z:
    for name, view in answers.items():
        z.writestr(name + ".npy", npy_bytes(view))
print(json.dumps({"module": _core.__file__, "simd": _core.simd_path(), "python": sys.version.split()[0],
                  "platform": sys.platform, "numpy": numpy.__version__ if numpy else None,
                  "answers": sorted(answers)}))
