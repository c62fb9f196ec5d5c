"""Ray throughput of the core on the paper's experiment: nearest hit and each method preset.

    python benchmarks/trace_throughput.py [--quick]     (`make bench`, `make bench-quick`)

The Stanford bunny's 35,947 vertices with area-weighted normals and k-NN radii (the
paper's 35,945-point cloud), one ray per pixel at 640x480. Prints one table: BVH build
time; rays per second of the plain nearest-hit trace(), of trace_surface() under each
method preset (the ε-window query and the visibility rules; the cloud treated as closed,
as the paper does), and of render() with the full method, on 1 thread and on all cores;
and the paper's own figure as the reference row. Without ../shared (a user's clone), an
analytic sphere of the same size stands in for the bunny, and the table says so.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from meshes import SHARED_MESHES, area_samples, fit_camera, icosphere, read_obj, vertex_cloud  # noqa: E402
from splat_tracer import core, spacing  # noqa: E402

WIDTH, HEIGHT = 640, 480
PAPER_SECONDS = (7.0, 10.0)  # Beddiaf & Babahenini, sec. IV: 35,945 points at 640x480


def load_cloud():
    bunny = SHARED_MESHES / "stanford-bunny.obj"
    if bunny.is_file():
        return "stanford bunny (vertices)", *vertex_cloud(*read_obj(bunny))
    return "sphere stand-in (no ../shared)", *area_samples(*icosphere(5), 35947)


def timed(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer repetitions (CI)")
    args = ap.parse_args(argv)
    repeats = 3 if args.quick else 7

    name, positions, normals = load_cloud()
    origin, local = core.local_frame(positions)
    radii, _ = spacing.knn_spacing(local)
    cores = core.hardware_threads()
    build_s, scene = timed(lambda: core.Scene(local, normals, radii, closed=True), repeats)
    cam = fit_camera(core, local, WIDTH, HEIGHT)
    origins, dirs = cam.rays(WIDTH, HEIGHT)
    n_rays = len(origins)

    full = core.Method.preset("FULL")
    rows = []
    for threads in sorted({1, cores}):
        t_trace, hits = timed(lambda: scene.trace(origins, dirs, normals=False, threads=threads), repeats)
        rows.append(("core trace(), nearest hit", threads, t_trace))
        for preset in core.PRESETS:
            method = core.Method.preset(preset)
            t, _ = timed(lambda: scene.trace_surface(origins, dirs, method, threads=threads), repeats)
            rows.append((f"core trace_surface(), {preset.lower().replace('_', '-')} method", threads, t))
        t_render, _ = timed(lambda: scene.render(cam, WIDTH, HEIGHT, threads=threads, method=full), repeats)
        rows.append(("core render(), full method, headlight shading", threads, t_render))
    coverage = float((hits.id >= 0).mean())

    stats = scene.bvh_stats()
    print(f"# Trace throughput: {name}, {len(local):,} splats, {WIDTH}x{HEIGHT} = {n_rays:,} rays, "
          f"{coverage:.1%} of pixels hit")
    print(f"# BVH: built in {build_s * 1e3:.1f} ms on {cores} threads; {stats['nodes']:,} nodes, "
          f"depth {stats['depth']}, median of {repeats} runs each\n")
    print("| renderer | threads | time (s) | Mrays/s | vs nearest hit |")
    print("|---|---:|---:|---:|---:|")
    nearest = {threads: t for name, threads, t in rows if name.startswith("core trace()")}
    for name, threads, t in rows:
        print(f"| {name} | {threads} | {t:.3f} | {n_rays / t / 1e6:.2f} | {t / nearest[threads]:.2f}x |")
    lo, hi = PAPER_SECONDS
    print(f"| paper (Beddiaf & Babahenini), full method, 35,945 points | ? | {lo:.0f}-{hi:.0f} | "
          f"{n_rays / hi / 1e6:.3f}-{n_rays / lo / 1e6:.3f} | |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
