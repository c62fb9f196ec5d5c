"""Import speed and memory: Splat Tracer's importer beside Blender's own PLY importer and
Open3D, in the same run, on files this script writes.

    python -m benchmarks.import_speed [--quick] [--points N] [--output DIR] [--open3d-python PY]

The cloud: N points sampled uniformly at random over a wavy 1 km x 1 km terrain (a height
field, its true normals known), with colours and, for LAS, intensity and classification.
Two files: a binary little-endian PLY (x y z nx ny nz as float32, red green blue as uchar:
what scanning software exports) and a LAS 1.4 file (point format 7: 16-bit colour,
millimetre scale, a UTM-like offset). Every case runs in a fresh Python process, so that
its peak memory is its own: the peak RSS (which sees numpy's and native allocations, unlike
tracemalloc) is reset to the current RSS just before the case (Linux's clear_refs) and read
after it; memory per point is that peak minus the RSS before the case (Python, bpy, the
extension loaded), over N.

Cases:
- Splat Tracer, PLY with normals: read, checks, origin, k-NN radii, the Blender object
  (the import operator's own functions: importer.load, then create_objects).
- Splat Tracer, LAS: the same; LAS has no normals, so they are estimated and oriented:
  the table gives the import with that step and without it (the same pipeline given +Z
  normals, as if the file had them: the radii then need their own neighbour search).
- Splat Tracer, normal estimation alone: PCA over 16 neighbours and the orientation (on
  the PLY's points, its normals ignored).
- Blender's PLY importer (bpy.ops.wm.ply_import; a mesh of vertices, no radii, no analysis).
- Open3D: read_point_cloud of the PLY; estimate_normals with 16 nearest neighbours (PCA
  only: its consistent orientation, orient_normals_consistent_tangent_plane, is not run).
  In its own virtual environment (build/o3d by default; `make bench` creates it); the rows
  are skipped, saying why, when it is missing.

Timings are wall-clock seconds of one run each: on a machine shared with other work they
vary by tens of percent.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

FULL_POINTS = 10_000_000
QUICK_POINTS = 20_000
TERRAIN_SIZE = 1000.0           # metres: the terrain is TERRAIN_SIZE x TERRAIN_SIZE
LAS_OFFSET = (500000.0, 5000000.0, 0.0)  # a UTM-like easting/northing, as aerial scans have
LAS_SCALE = 0.001               # millimetres, the usual LAS scale
TARGET_IMPORT_SECONDS = 5.0     # issue 10: 10M-point PLY and LAS imports, without normal estimation
TARGET_NORMALS_SECONDS = 60.0   # issue 10: normal estimation of 10M points
NORMAL_K = 16                   # neighbours for PCA normals, ours and Open3D's alike
DEFAULT_O3D = ROOT / "build" / "o3d" / "bin" / "python"


# --- the files ---------------------------------------------------------------------------

def terrain(n: int, seed: int = 0):
    """(positions, normals, rgb8) of n points on z = h(x, y)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, TERRAIN_SIZE, (n, 2))
    a, b = 2 * np.pi / 170.0, 2 * np.pi / 230.0  # wavelengths of the hills
    x, y = xy[:, 0], xy[:, 1]
    z = 12.0 * np.sin(a * x) * np.cos(b * y) + 3.0 * np.sin(0.05 * x + 0.02 * y)
    dzdx = 12.0 * a * np.cos(a * x) * np.cos(b * y) + 3.0 * 0.05 * np.cos(0.05 * x + 0.02 * y)
    dzdy = -12.0 * b * np.sin(a * x) * np.sin(b * y) + 3.0 * 0.02 * np.cos(0.05 * x + 0.02 * y)
    nrm = np.column_stack([-dzdx, -dzdy, np.ones(n)])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    shade = np.clip((z - z.min()) / max(np.ptp(z), 1e-9), 0, 1)
    rgb = np.column_stack([80 + 120 * shade, 140 - 40 * shade, 60 + 30 * shade]).astype(np.uint8)
    return np.column_stack([xy, z]), nrm, rgb


def write_files(n: int, folder: Path) -> tuple[Path, Path]:
    folder.mkdir(parents=True, exist_ok=True)
    ply_path, las_path = folder / f"terrain_{n}.ply", folder / f"terrain_{n}.las"
    if ply_path.is_file() and las_path.is_file():
        return ply_path, las_path
    import laspy

    pos, nrm, rgb = terrain(n)
    rows = np.empty(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"),
                              ("nz", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    for k, c in enumerate("xyz"):
        rows[c], rows["n" + c] = pos[:, k], nrm[:, k]
    for k, c in enumerate(("red", "green", "blue")):
        rows[c] = rgb[:, k]
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % n
              + "".join(f"property float {c}\n" for c in ("x", "y", "z", "nx", "ny", "nz"))
              + "".join(f"property uchar {c}\n" for c in ("red", "green", "blue")) + "end_header\n")
    with open(ply_path, "wb") as f:
        f.write(header.encode("ascii"))
        rows.tofile(f)
    las = laspy.LasData(laspy.LasHeader(point_format=7, version="1.4"))
    las.header.offsets, las.header.scales = np.array(LAS_OFFSET), np.full(3, LAS_SCALE)
    geo = pos + np.array(LAS_OFFSET)
    las.x, las.y, las.z = geo[:, 0], geo[:, 1], geo[:, 2]
    las.red, las.green, las.blue = (rgb.astype(np.uint16) * 257).T
    las.intensity = (np.arange(n) % 4096).astype(np.uint16)
    las.classification = np.full(n, 2, np.uint8)  # ground
    las.write(str(las_path))
    return ply_path, las_path


# --- one case, in its own process ---------------------------------------------------------

class Stages:
    """A progress callback that records when each stage starts (by its message)."""

    NAMES = (("reading", "read"), ("read ", "checks"), ("point budget", "budget"), ("neighbour tree", "normals"),
             ("estimating normals", "normals"), ("orienting", "normals"), ("splat radii", "radii"))

    def __init__(self):
        self.t0 = time.perf_counter()
        self.marks = []  # (time, stage)

    def __call__(self, fraction, message):
        stage = next((name for prefix, name in self.NAMES if message.startswith(prefix)), None)
        if stage and (not self.marks or self.marks[-1][1] != stage):
            self.marks.append((time.perf_counter() - self.t0, stage))

    def durations(self, end: float) -> dict:
        out = {}
        for (t, stage), nxt in zip(self.marks, self.marks[1:] + [(end, None)]):
            out[stage] = out.get(stage, 0.0) + nxt[0] - t
        return out


def _status(field: str) -> int:
    """A memory figure of this process in bytes from /proc/self/status (VmRSS, VmHWM)."""
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    raise KeyError(field)


def _start_peak() -> int:
    """Resets the process's peak RSS to its current RSS (Linux: /proc/self/clear_refs 5) and
    returns that RSS: the case's peak is then its own, not start-up's (importing bpy peaks
    higher than a 10M-point mesh adds, which ru_maxrss alone would hide). Without /proc:
    ru_maxrss, the peak so far."""
    try:
        with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
            f.write("5")
        return _status("VmRSS")
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _peak_since(base: int) -> int:
    try:
        return _status("VmHWM") - base
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - base


def run_case(case: str, path: str) -> dict:
    """One measurement in this process: wall seconds and peak memory beyond the start."""
    out = {"case": case}
    if case in ("ours", "ours_given_normals", "ours_normals", "blender"):
        from tools import dev_extension

        home = dev_extension.isolate_user_dirs()
        import bpy

        dev_extension.enable_from_source(home)
        bpy.ops.wm.read_homefile(use_empty=True)
        ext = next(m for name, m in sys.modules.items()
                   if name.startswith("bl_ext.") and name.endswith(".splat_tracer.operators.import_cloud"))
        importer = next(m for name, m in sys.modules.items()
                        if name.startswith("bl_ext.")
                        and name.endswith(".splat_tracer.splat_tracer.pointcloud.importer"))
        normals, readers, prepare = (next(m for name, m in sys.modules.items() if name.startswith("bl_ext.")
                                          and name.endswith(f".splat_tracer.splat_tracer.pointcloud.{module}"))
                                     for module in ("normals", "readers", "prepare"))
        base = _start_peak()
        t0 = time.perf_counter()
        if case in ("ours", "ours_given_normals"):
            stages = Stages()
            if case == "ours":
                prep = importer.load(path, importer.ImportOptions(), stages)
            else:  # the import without estimating normals: as if the file had them
                from dataclasses import replace

                stages(0.0, "reading")
                cloud = readers.read_cloud(path)
                cloud = replace(cloud, normals=np.tile(np.float32([0, 0, 1]), (len(cloud), 1)), oriented=True)
                stages(0.2, "read ")
                handed = [cloud]  # handed over as importer.load does: prepare lets go of the float64 positions
                del cloud
                prep = prepare.prepare(handed.pop(), path, progress=stages)
            t_load = time.perf_counter() - t0
            out["points"] = len(prep.local)
            ext.create_objects(bpy.context, [(path, prep)], lambda p: p.notes(6), consume=True)  # as the operator
            out["seconds"] = time.perf_counter() - t0
            out["stages"] = stages.durations(t_load)
            out["stages"]["blender object"] = out["seconds"] - t_load
        elif case == "ours_normals":
            from plyfile import PlyData

            v = PlyData.read(path)["vertex"].data
            pts = np.column_stack([v[c].astype(np.float64) for c in "xyz"])
            del v
            base = _start_peak()
            t0 = time.perf_counter()
            graph = np.empty((len(pts), normals.GRAPH_K + 1), np.int32)  # as prepare.py does
            axes = normals.estimate(pts, NORMAL_K, graph=graph)
            t_est = time.perf_counter() - t0
            result = normals.orient(pts, axes, "PROPAGATE", graph=graph)
            out["seconds"] = time.perf_counter() - t0
            out["stages"] = {"estimate (PCA)": t_est, "orient": out["seconds"] - t_est}
            out["points"] = len(pts)
            out["upward"] = float((result.normals[:, 2] > 0).mean())
        else:
            bpy.ops.wm.ply_import(filepath=path)
            out["seconds"] = time.perf_counter() - t0
            out["points"] = len(bpy.context.active_object.data.vertices)
        out["peak_bytes"] = _peak_since(base)
        return out
    import open3d as o3d  # the Open3D cases run in Open3D's own environment

    base = _start_peak()
    t0 = time.perf_counter()
    pcd = o3d.io.read_point_cloud(path)
    out["read_seconds"] = time.perf_counter() - t0
    out["points"] = len(pcd.points)
    if case == "open3d_normals":
        pcd.normals = o3d.utility.Vector3dVector()  # drop the file's: estimate them
        t1 = time.perf_counter()
        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(NORMAL_K))
        out["seconds"] = time.perf_counter() - t1
    else:
        out["seconds"] = out["read_seconds"]
    out["peak_bytes"] = _peak_since(base)
    return out


def spawn(python: str, case: str, path: Path) -> dict:
    cmd = [python, "-m", "benchmarks.import_speed", "--case", case, "--file", str(path)]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=str(ROOT))
    lines = [line for line in proc.stdout.splitlines() if line.startswith("{")]
    if proc.returncode != 0 or not lines:
        return {"case": case, "error": (proc.stderr.strip().splitlines() or ["no output"])[-1]}
    return json.loads(lines[-1])


# --- the report ---------------------------------------------------------------------------

ROWS = [  # (key, renderer, file, what)
    ("ours_ply", "Splat Tracer import", "PLY", "read, checks, k-NN radii, Blender object (file has normals)"),
    ("ours_las", "Splat Tracer import", "LAS", "the same, normals not estimated (given as +Z, as if the file had them)"),
    ("ours_las_total", "Splat Tracer import", "LAS", "all of it, normals estimated and oriented"),
    ("blender_ply", "Blender `wm.ply_import`", "PLY", "a mesh of vertices (no radii, no analysis)"),
    ("open3d_ply", "Open3D `read_point_cloud`", "PLY", "a PointCloud in memory (no Blender object)"),
    ("ours_normals", "Splat Tracer normals", "-", "PCA (16 neighbours) + orientation along the neighbour graph"),
    ("ours_pca", "Splat Tracer normals", "-", "PCA (16 neighbours) alone"),
    ("open3d_normals", "Open3D `estimate_normals`", "-", "PCA (16 neighbours), no consistent orientation"),
]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help=f"{QUICK_POINTS:,} points (CI)")
    ap.add_argument("--points", type=int, default=0, help=f"points (default {FULL_POINTS:,})")
    ap.add_argument("--output", default=str(HERE / "results"))
    ap.add_argument("--open3d-python", default=str(DEFAULT_O3D), help="a Python with open3d (default: build/o3d)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="runs of every case (in rounds: each round runs every case once); the table gives each "
                         "case's median run and the others beside it (`make bench`: 3)")
    ap.add_argument("--case", help=argparse.SUPPRESS)
    ap.add_argument("--file", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.case:
        print(json.dumps(run_case(args.case, args.file)), flush=True)
        return 0
    n = args.points or (QUICK_POINTS if args.quick else FULL_POINTS)
    t0 = time.perf_counter()
    ply_path, las_path = write_files(n, ROOT / "build" / "import_bench")
    print(f"import_speed: {n:,} points; files written in {time.perf_counter() - t0:.1f} s", flush=True)
    me = sys.executable
    o3d = args.open3d_python if Path(args.open3d_python).is_file() else None
    o3d_why = None
    if o3d is None:
        o3d_why = f"no Python with open3d at {args.open3d_python} (`make bench` creates build/o3d)"
    results = {}
    runs = [("ours_ply", me, "ours", ply_path), ("ours_las", me, "ours_given_normals", las_path),
            ("ours_las_total", me, "ours", las_path),
            ("blender_ply", me, "blender", ply_path), ("ours_normals", me, "ours_normals", ply_path)]
    if o3d:
        runs += [("open3d_ply", o3d, "open3d_read", ply_path), ("open3d_normals", o3d, "open3d_normals", ply_path)]
    repeat = max(1, args.repeat)
    every = {key: [] for key, *_ in runs}
    for _ in range(repeat):  # in rounds: a slow spell of the machine falls on every case alike
        for key, python, case, path in runs:
            r = spawn(python, case, path)
            every[key].append(r)
            print(f"import_speed: {key}: " + (f"{r['seconds']:.2f} s, peak {r['peak_bytes'] / n:.0f} B/point"
                                              if "seconds" in r else f"failed: {r['error']}"), flush=True)
            if key.startswith("open3d") and "error" in r and o3d_why is None:
                o3d_why = f"Open3D failed: {r['error']}"
    for key, rs in every.items():  # the median run (its stages and memory), all runs' times beside it
        ok = sorted((r for r in rs if "seconds" in r), key=lambda r: r["seconds"])
        results[key] = dict(ok[(len(ok) - 1) // 2], runs=[r["seconds"] for r in rs if "seconds" in r]) if ok else rs[0]
    nm = results.get("ours_normals", {})
    if "stages" in nm:
        pca = sorted(r["stages"]["estimate (PCA)"] for r in every["ours_normals"] if "stages" in r)
        results["ours_pca"] = dict(nm, seconds=pca[(len(pca) - 1) // 2], peak_bytes=None, runs=pca)
    report = {"points": n, "cpus": os.cpu_count(), "repeat": repeat, "results": results, "open3d_skipped": o3d_why,
              "targets": {"import_seconds": TARGET_IMPORT_SECONDS, "normals_seconds": TARGET_NORMALS_SECONDS}}
    out_dir = Path(args.output)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "import_speed.json").write_text(json.dumps(report, indent=1))
    lines = [f"# Import speed: {n:,} points", "",
             f"`python -m benchmarks.import_speed`{' --quick' if args.quick else ''}"
             f"{f' --repeat {repeat}' if repeat > 1 else ''}: "
             + ("one run of each case" if repeat == 1 else f"{repeat} runs of each case, in rounds; the median run")
             + f", each in a fresh process, {os.cpu_count()} CPUs (shared with other work: timings vary by tens of "
             "percent). Memory: the case's peak RSS beyond the process's before it, per point.", "",
             "| what | file | does | time (s) | runs (s) | peak memory (bytes/point) |", "|---|---|---|---:|---|---:|"]
    for key, who, file, what in ROWS:
        r = results.get(key)
        if r is None:
            if key.startswith("open3d"):
                lines.append(f"| {who} | {file} | skipped: {o3d_why} | | | |")
            continue
        if "error" in r:
            lines.append(f"| {who} | {file} | failed: {r['error']} | | | |")
            continue
        mem = "" if r.get("peak_bytes") is None else f"{r['peak_bytes'] / n:.0f}"
        runs_s = ", ".join(f"{t:.2f}" for t in r.get("runs", [r["seconds"]]))
        lines.append(f"| {who} | {file} | {what} | {r['seconds']:.2f} | {runs_s} | {mem} |")
    for key in ("ours_ply", "ours_las", "ours_las_total", "ours_normals"):
        if "stages" in results.get(key, {}):
            st = results[key]["stages"]
            lines.append("")
            lines.append(f"{key} stages (s): " + ", ".join(f"{k} {v:.2f}" for k, v in st.items()))
    (out_dir / "import_speed.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
