"""Scale: building and rendering millions of splats (issue #12's scale targets).

    python -m benchmarks.scale [--quick] [--sizes 1M,10M,100M] [--no-embree]
                               (`make bench`: 1M and 10M; `make bench-quick`: 1M, --quick)

A closed torus (major radius 1, minor 0.4) sampled uniformly by area -- no external data --
with analytic normals and radii that cover each point with about three discs, on a mesh
floor, lit by one sun that casts the torus' shadow onto the floor. For each size it prints:

- the build of SplatCloud with the default settings (threads=0: all cores) and with 1
  thread (the speed-up from cores), median of interleaved runs;
- bytes per splat kept after the build, from the core's own accounting (Scene.bvh_stats()
  'bytes') and from the process' resident memory (RSS after the build minus before, the
  input arrays already freed), and the peak while building (input arrays included);
- a 1920x1080 frame of RenderScene with the full method, 1 sample, the sun's shadow
  rays and no bounce (the integrator path Blender uses);
- Embree 3's build of the same discs (benchmarks/embree_harness.cpp, its own
  oriented-disc primitive, quality medium, on all cores), when libembree-dev is there and
  for up to 20M discs.

Timings on a shared machine are noisy: the build times are medians of `--rounds` runs, the
default-threads and 1-thread builds interleaved.
"""
from __future__ import annotations

import argparse
import gc
import json
import math
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

from splat_tracer.render.camera import Camera  # noqa: E402
from splat_tracer.render.method import Method  # noqa: E402
from splat_tracer.render.scene import Instance, Mesh, RenderScene  # noqa: E402
from splat_tracer.render.shading import Light, Material, RenderSettings, World  # noqa: E402
from splat_tracer.render.splats import SplatCloud, simd_path  # noqa: E402

R_MAJOR, R_MINOR = 1.0, 0.4
AREA = 4 * math.pi ** 2 * R_MAJOR * R_MINOR
COVER = 3.0  # discs covering a surface point on average
EMBREE_MAX = 20_000_000


def torus_cloud(n: int, seed: int = 1, chunk: int = 5_000_000):
    """n splats on the torus, uniform by area (rejection on the minor angle), float32."""
    rng = np.random.default_rng(seed)
    centres = np.empty((n, 3), np.float32)
    normals = np.empty((n, 3), np.float32)
    done = 0
    while done < n:
        m = min(chunk, n - done)
        # Area density on the torus is proportional to R + r cos(v): accept v with that weight.
        v = rng.uniform(0, 2 * np.pi, 2 * m)
        keep = rng.uniform(0, R_MAJOR + R_MINOR, 2 * m) < R_MAJOR + R_MINOR * np.cos(v)
        v = v[keep][:m]
        m = len(v)
        u = rng.uniform(0, 2 * np.pi, m)
        cu, su, cv, sv = np.cos(u), np.sin(u), np.cos(v), np.sin(v)
        ring = R_MAJOR + R_MINOR * cv
        centres[done:done + m] = np.column_stack([ring * cu, ring * su, R_MINOR * sv + R_MINOR + 0.05])
        normals[done:done + m] = np.column_stack([cv * cu, cv * su, sv])
        done += m
    radius = math.sqrt(COVER * AREA / (math.pi * n))
    return centres, normals, np.full(n, radius, np.float32)


def floor_mesh(half: float = 3.0) -> Mesh:
    v = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]], np.float32)
    return Mesh(v, np.array([[0, 1, 2], [0, 2, 3]]))


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096


def kept_rss(n_splats: int) -> float:
    """Bytes per splat the process keeps for a built scene, measured in a fresh process: RSS
    after the build with the input arrays freed (and freed heap handed back to the system)
    minus RSS before the input was made; and the peak (input included) the same way."""
    code = f"""
import ctypes, gc
from benchmarks import scale
from splat_tracer.render.camera import Camera
from splat_tracer.render.method import Method
from splat_tracer.render.scene import Instance, Mesh, RenderScene
from splat_tracer.render.splats import SplatCloud, simd_path
before = scale.rss_bytes()
c, n, r = scale.torus_cloud({n_splats})
s = SplatCloud(c, n, r, closed=True)
del c, n, r
gc.collect()
ctypes.CDLL("libc.so.6").malloc_trim(0)
import resource
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
print((scale.rss_bytes() - before) / {n_splats}, (peak - before) / {n_splats})
"""
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    if run.returncode:
        return float("nan"), float("nan")
    kept, peak = run.stdout.strip().splitlines()[-1].split()
    return float(kept), float(peak)


def timed_builds(c, n, r, rounds: int) -> dict:
    """Median build seconds with threads=0 (default) and threads=1, interleaved."""
    times = {0: [], 1: []}
    for _ in range(rounds):
        for threads in (0, 1):
            t0 = time.perf_counter()
            s = SplatCloud(c, n, r, closed=True, threads=threads)
            times[threads].append(time.perf_counter() - t0)
            del s
            gc.collect()
    return {k: statistics.median(v) for k, v in times.items()}


def embree_build(c, n, r, work: Path) -> float | None:
    from benchmarks import trace_throughput as tt
    if tt.embree_available(install=False):
        return None
    work.mkdir(parents=True, exist_ok=True)
    exe = work / "embree_harness"
    if not exe.exists() or exe.stat().st_mtime < tt.HARNESS.stat().st_mtime:
        if subprocess.run(["g++", "-O2", "-std=c++17", str(tt.HARNESS), "-o", str(exe), "-lembree3", "-pthread"],
                          capture_output=True).returncode:
            return None
    np.column_stack([c, r, n]).astype(np.float32).tofile(work / "discs.f32")
    # One ray: only the build time is wanted here.
    np.array([[0, 0, 10, 0, 0, -1]], np.float32).tofile(work / "rays.f32")
    import os
    run = subprocess.run([str(exe), str(work / "discs.f32"), str(work / "rays.f32"), str(work / "hits.f32"),
                          str(os.cpu_count()), "1"], input="1\n", capture_output=True, text=True)
    (work / "discs.f32").unlink()
    if run.returncode:
        return None
    return json.loads(run.stdout.strip().splitlines()[-1])["build_s"]


def frame(scene: SplatCloud, width: int, height: int) -> tuple[float, dict]:
    sun = Light(type="SUN", power=3.0, direction=(-0.4, 0.3, -1.0))
    rs = RenderScene([Instance(scene, materials=(Material(base_colour=(0.8, 0.5, 0.3)),)),
                      Instance(floor_mesh())], [sun], World(colour=(0.2, 0.2, 0.25)))
    cam = Camera.look_at((0.0, -3.2, 2.4), (0.0, 0.0, 0.3), fov_y=40.0, aspect=width / height)
    settings = RenderSettings(samples=1, diffuse_bounces=0, glossy_bounces=0, transmission_bounces=0)
    t0 = time.perf_counter()
    fr = rs.render(cam, width, height, settings, method=Method.preset("FULL"))
    return time.perf_counter() - t0, fr.counters


def parse_size(s: str) -> int:
    s = s.strip().upper()
    mult = {"K": 10 ** 3, "M": 10 ** 6}.get(s[-1], 1)
    return int(float(s.rstrip("KM")) * mult)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="1M splats, one round, 960x540 (CI)")
    ap.add_argument("--sizes", default=None, help="comma-separated splat counts (1M,10M,100M)")
    ap.add_argument("--rounds", type=int, default=None, help="interleaved build rounds (default 3, quick 1)")
    ap.add_argument("--no-embree", action="store_true")
    args = ap.parse_args(argv)
    sizes = [parse_size(s) for s in (args.sizes or ("1M" if args.quick else "1M,10M")).split(",")]
    rounds = args.rounds or (1 if args.quick else 3)
    width, height = (960, 540) if args.quick else (1920, 1080)
    print(f"scale: torus, closed, {COVER:g} discs per point; hardware threads: {core_threads()}; "
          f"box and disc tests in {simd_path()}; "
          f"build medians of {rounds} interleaved round(s); frame {width}x{height}, full method, 1 sample, one sun "
          f"with shadows, on all threads. Shared machine: timings vary by +-25 %.")
    print("| splats | build, default threads (s) | build, 1 thread (s) | speed-up | Embree build (s) "
          "| kept B/splat (core) | kept B/splat (RSS) | peak B/splat (RSS, input included) | frame (s) | shadow rays |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n_splats in sizes:
        # Memory first, in its own process, before this one holds any splat.
        rss_kept, rss_peak = kept_rss(n_splats)
        c, n, r = torus_cloud(n_splats)
        # Embree's copy and BVH of 100M discs would not fit beside ours: up to 20M.
        embree = None if args.no_embree or n_splats > EMBREE_MAX else embree_build(c, n, r, Path("build") / "bench-scale")
        builds = timed_builds(c, n, r, rounds) if rounds > 0 else {0: float("nan"), 1: float("nan")}
        scene = SplatCloud(c, n, r, closed=True)
        del c, n, r
        gc.collect()
        core_kept = scene.bvh_stats().get("bytes", float("nan")) / n_splats
        seconds, counters = frame(scene, width, height)
        label = f"{n_splats / 1e6:g}M"
        em = f"{embree:.2f}" if embree is not None else "n/a"
        print(f"| {label} | {builds[0]:.2f} | {builds[1]:.2f} | {builds[1] / builds[0]:.2f}x | {em} "
              f"| {core_kept:.1f} | {rss_kept:.1f} | {rss_peak:.0f} | {seconds:.2f} | {counters.get('shadow_rays', 0):,} |", flush=True)
        del scene
        gc.collect()
    return 0


def core_threads() -> int:
    from splat_tracer import _core
    return _core.hardware_threads()


if __name__ == "__main__":
    sys.exit(main())
