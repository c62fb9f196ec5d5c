"""Ray throughput of the core on the paper's experiment: nearest hit and each method preset.

    python -m benchmarks.trace_throughput [--quick]     (`make bench`, `make bench-quick`)

The Stanford bunny's 35,947 vertices with area-weighted normals and k-NN radii (the
paper's 35,945-point cloud), one ray per pixel at 640x480. Prints one table: BVH build
time; rays per second of the plain nearest-hit trace(), of trace_surface() under each
method preset (the ε-window query and the visibility rules; the cloud treated as closed,
as the paper does), and of render() with the full method, on 1 thread and on all cores --
the rays in packets of 4x4 pixels, and for the nearest hit and the full method also one ray
at a time and (where the CPU runs the AVX2 kernels) with the SSE2 ones;
beside them, on the same discs, rays and threads, Embree 3's own oriented-disc primitive
(rtcIntersect1 one ray at a time, rtcIntersect16 in 4x4 pixel packets; embree_harness.cpp,
built against Debian's libembree-dev, installed when missing and possible -- the row is
skipped with a message otherwise), with its hits checked against the core's; and the
paper's own figure. Every row is timed once per round, the core's and Embree's interleaved
(the machine is shared: a change in load then falls on all rows alike); medians of the
rounds. Without ../shared (a user's clone), an analytic sphere of the same size
stands in for the bunny, and the table says so.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

from benchmarks.meshes import SHARED_MESHES, area_samples, fit_camera, icosphere, read_obj, vertex_cloud  # noqa: E402
from splat_tracer import _core  # noqa: E402
from splat_tracer.pointcloud import spacing  # noqa: E402
from splat_tracer.pointcloud.neighbours import local_frame  # noqa: E402
from splat_tracer.render.camera import PACKET_RAYS, packet_order  # noqa: E402
from splat_tracer.render.method import PRESETS, Method  # noqa: E402
from splat_tracer.render.splats import SplatCloud, hardware_threads, simd_path  # noqa: E402

WIDTH, HEIGHT = 640, 480
PAPER_SECONDS = (7.0, 10.0)  # Beddiaf & Babahenini, sec. IV: 35,945 points at 640x480


def load_cloud():
    bunny = SHARED_MESHES / "stanford-bunny.obj"
    if bunny.is_file():
        return "stanford bunny (vertices)", *vertex_cloud(*read_obj(bunny))
    return "sphere stand-in (no ../shared)", *area_samples(*icosphere(5), 35947)


def sse2(fn):
    """fn() with the packet kernels held to SSE2 (where the CPU would run AVX2)."""
    before = _core._use_avx2(False)
    try:
        return fn()
    finally:
        _core._use_avx2(before)


def timed(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


EMBREE_HEADER = Path("/usr/include/embree3/rtcore.h")
HARNESS = HERE / "embree_harness.cpp"
# Hits agree when both miss or their distances differ by at most this, relative (issue #12).
AGREE_RELATIVE = 1e-4


def embree_available(install: bool) -> str | None:
    """None when Embree 3's headers and library are there (installing Debian's libembree-dev
    when missing, allowed and possible), else why not."""
    if EMBREE_HEADER.is_file():
        return None
    if not install:
        return "libembree-dev is not installed (the quick run does not install it)"
    if shutil.which("apt-get") is None or os.geteuid() != 0:
        return "libembree-dev is not installed and cannot be installed here (no apt-get or not root)"
    for cmd in (["apt-get", "update", "-qq"], ["apt-get", "install", "-y", "-qq", "libembree-dev"]):
        if subprocess.run(cmd, capture_output=True, env={**os.environ, "DEBIAN_FRONTEND": "noninteractive"}).returncode:
            return f"installing libembree-dev failed ({' '.join(cmd)})"
    return None if EMBREE_HEADER.is_file() else "libembree-dev installed without embree3/rtcore.h"


def embree_runner(local, normals, radii, origins, dirs, install, work: Path):
    """A function run(threads) -> {'intersect1_s', 'intersect16_s', 'build_s'} (one round of
    the harness: its own build, then each query once) writing rtcIntersect1's hit distances
    to work/hits.f32, or (None, reason)."""
    reason = embree_available(install)
    if reason:
        return None, reason
    work.mkdir(parents=True, exist_ok=True)
    exe = work / "embree_harness"
    if not exe.exists() or exe.stat().st_mtime < HARNESS.stat().st_mtime:
        build = subprocess.run(["g++", "-O2", "-std=c++17", str(HARNESS), "-o", str(exe), "-lembree3", "-pthread"],
                               capture_output=True, text=True)
        if build.returncode:
            return None, f"the Embree harness did not build: {build.stderr.strip()[-300:]}"
    n = np.asarray(normals, np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    discs = np.column_stack([local, radii, n]).astype(np.float32)
    discs.tofile(work / "discs.f32")
    np.column_stack([origins, dirs]).astype(np.float32).tofile(work / "rays.f32")

    def run(threads: int) -> dict:
        out = subprocess.run([str(exe), str(work / "discs.f32"), str(work / "rays.f32"), str(work / "hits.f32"),
                              str(threads), "1"], input=f"{WIDTH}\n", capture_output=True, text=True)
        if out.returncode:
            raise RuntimeError(f"the Embree harness failed: {out.stderr.strip()[-300:]}")
        return json.loads(out.stdout.strip().splitlines()[-1])

    return run, None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer repetitions (CI)")
    args = ap.parse_args(argv)
    repeats = 3 if args.quick else 7

    name, positions, normals = load_cloud()
    origin, local = local_frame(positions)
    radii, _ = spacing.knn_spacing(local)
    cores = hardware_threads()
    build_s, scene = timed(lambda: SplatCloud(local, normals, radii, closed=True), repeats)
    cam = fit_camera(local, WIDTH, HEIGHT)
    origins, dirs = cam.rays(WIDTH, HEIGHT)
    n_rays = len(origins)
    # The core's rows take the rays in 4x4 pixel tiles (packet_order: 16 consecutive
    # rays make one packet), as Embree's rtcIntersect16 row does; Embree's rtcIntersect1
    # and the harness take them row by row (it cuts its own tiles).
    order = packet_order(WIDTH, HEIGHT)
    tile_o, tile_d = np.ascontiguousarray(origins[order]), np.ascontiguousarray(dirs[order])

    full = Method.preset("FULL")
    # Every row is timed once per round and the rounds interleave the core's rows with
    # Embree's, so that a change in the machine's load (it is shared) falls on all of them
    # alike; each row's time is its median over the rounds.
    runs = []  # (row name, threads, function)
    thread_counts = sorted({1, cores})
    for threads in thread_counts:
        runs.append(("core trace(), nearest hit", threads,
                     lambda threads=threads: scene.trace(tile_o, tile_d, normals=False, threads=threads)))
        runs.append(("core trace(), nearest hit, one ray at a time", threads,
                     lambda threads=threads: scene.trace(tile_o, tile_d, normals=False, threads=threads,
                                                         packets=False)))
        for preset in PRESETS:
            method = Method.preset(preset)
            runs.append((f"core trace_surface(), {preset.lower().replace('_', '-')} method", threads,
                         lambda threads=threads, method=method: scene.trace_surface(tile_o, tile_d, method,
                                                                                    threads=threads)))
        if "AVX2" in simd_path():  # the baseline every other x86-64 CPU runs
            runs.append(("core trace(), nearest hit, SSE2 kernels", threads,
                         lambda threads=threads: sse2(lambda: scene.trace(tile_o, tile_d, normals=False,
                                                                          threads=threads))))
            runs.append(("core trace_surface(), full method, SSE2 kernels", threads,
                         lambda threads=threads: sse2(lambda: scene.trace_surface(tile_o, tile_d, full,
                                                                                  threads=threads))))
        runs.append(("core trace_surface(), full method, one ray at a time", threads,
                     lambda threads=threads: scene.trace_surface(tile_o, tile_d, full, threads=threads,
                                                                 packets=False)))
        runs.append(("core render(), full method, headlight shading", threads,
                     lambda threads=threads: scene.render(cam, WIDTH, HEIGHT, threads=threads, method=full)))
    embree_run, why_not = embree_runner(local, normals, radii, origins, dirs, install=not args.quick,
                                        work=HERE.parent / "build" / "embree")
    times = [[] for _ in runs]
    embree_times = {t: {"intersect1_s": [], "intersect16_s": [], "build_s": []} for t in thread_counts}
    hits = None
    for _ in range(repeats):
        for k, (_, _, fn) in enumerate(runs):
            t0 = time.perf_counter()
            result = fn()
            times[k].append(time.perf_counter() - t0)
            if k == 0:
                hits = result
        if embree_run is not None:
            for threads in thread_counts:
                one = embree_run(threads)
                for key, values in embree_times[threads].items():
                    values.append(one[key])
    rows = [(name, threads, statistics.median(ts)) for (name, threads, _), ts in zip(runs, times)]
    coverage = float((hits.id >= 0).mean())

    embree = None
    agreement = None
    if embree_run is not None:
        results = {t: {key: statistics.median(v) for key, v in r.items()} for t, r in embree_times.items()}
        embree_t = np.fromfile(HERE.parent / "build" / "embree" / "hits.f32", np.float32)
        embree = (results, embree_t)
        core_t = np.empty_like(hits.t)
        core_t[order] = hits.t  # back to row order
        both_miss = np.isinf(core_t) & np.isinf(embree_t)
        with np.errstate(invalid="ignore"):  # inf - inf where both miss
            close = np.abs(embree_t - core_t) <= AGREE_RELATIVE * np.abs(core_t)
        agreement = float((both_miss | close).mean())
        for threads, r in sorted(results.items()):
            rows.append(("Embree 3 rtcIntersect1, nearest hit", threads, r["intersect1_s"]))
            rows.append(("Embree 3 rtcIntersect16, 4x4 packets", threads, r["intersect16_s"]))

    stats = scene.bvh_stats()
    print(f"# Trace throughput: {name}, {len(local):,} splats, {WIDTH}x{HEIGHT} = {n_rays:,} rays, "
          f"{coverage:.1%} of pixels hit")
    print(f"# BVH: built in {build_s * 1e3:.1f} ms on {cores} threads; {stats['nodes']:,} 4-wide nodes, "
          f"box and disc tests in {simd_path()} (no -march=native; AVX2 chosen at run time where the CPU has it), rays in packets "
          f"of {PACKET_RAYS} (4x4 pixels) unless the row says one at a time; "
          f"depth {stats['depth']}; median of {repeats} interleaved rounds (every row once per round)\n")
    if embree is None:
        print(f"# Embree reference skipped: {why_not}\n")
    else:
        build_e = {t: r["build_s"] for t, r in embree[0].items()}
        print(f"# Embree 3 (oriented discs, build quality medium): built in {build_e[max(build_e)] * 1e3:.1f} ms on "
              f"{max(build_e)} threads; hits agree with the core's on {agreement:.3%} of the rays (both miss, or "
              f"t within {AGREE_RELATIVE:g} relative)\n")
    print("| renderer | threads | time (s) | Mrays/s | vs nearest hit | x Embree rtcIntersect1 |")
    print("|---|---:|---:|---:|---:|---:|")
    nearest = {threads: t for name, threads, t in rows if name == "core trace(), nearest hit"}
    reference = {threads: t for name, threads, t in rows if name.startswith("Embree 3 rtcIntersect1,")}
    for name, threads, t in rows:
        versus = f"{t / reference[threads]:.2f}" if threads in reference else ""
        print(f"| {name} | {threads} | {t:.3f} | {n_rays / t / 1e6:.2f} | {t / nearest[threads]:.2f}x | {versus} |")
    lo, hi = PAPER_SECONDS
    print(f"| paper (Beddiaf & Babahenini), full method, 35,945 points | ? | {lo:.0f}-{hi:.0f} | "
          f"{n_rays / hi / 1e6:.3f}-{n_rays / lo / 1e6:.3f} | | |")
    if agreement is not None and agreement < 0.999:
        print(f"# WARNING: only {agreement:.3%} of the hits agree with Embree's (issue #12 asks >= 99.9 %)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
