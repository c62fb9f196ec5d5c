"""An untextured scene's frame time before and after a change: this tree against a commit.

    python -m benchmarks.before_after [--commit e8ba060] [--before DIR] [--rounds N] [--quick] [--output DIR]

Issue #24 asks that an untextured scene pay nothing for the shader-node evaluator. The scene
is benchmarks/frame_time.py's (the bunny's vertex cloud on a mesh floor, one sun with
shadows, a grey world: no node but the Background and the Principled BSDF), rendered through
Blender by each tree's own add-on and core: the commit's tree (by default e8ba060, the last
commit before the evaluator) is exported with `git archive` into build/before_<commit>/ and
its core built there, unless --before names a built tree. Each round starts one Blender
process per tree, the two in alternating order (a change in the shared machine's load then
falls on both); each process renders a warm-up frame, then three 1-sample frames (their
median) and one 16-sample frame, and prints its times. The report gives each tree's median
over the rounds and the spread (lowest to highest), with the machine's load average.
--quick: 320x240 and two rounds, and only when the commit's tree is already built.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
KEYS = ("1 spp frame", "1 spp rendering", "1 spp CPU", "16 spp frame", "16 spp rendering", "16 spp CPU")
ROOT = HERE.parent


def probe(tree: Path, cloud_path: Path, width: int, height: int) -> None:
    """Run inside one Blender process: frame_time's scene through `tree`'s add-on, with the
    cloud the caller wrote (the same one for both trees: `bunny_cloud` looks for the meshes
    beside the tree, which a tree under build/ or /tmp does not have)."""
    import numpy as np

    sys.path.insert(0, str(tree))
    from tools import dev_extension

    assert dev_extension.REPO_ROOT == tree, (dev_extension.REPO_ROOT, tree)
    work = tree / "build" / "before_after"
    work.mkdir(parents=True, exist_ok=True)
    dev_extension.isolate_user_dirs(str(work / "blender_user"))
    import bpy

    dev_extension.enable_from_source(work)
    from benchmarks import frame_time
    from splat_tracer.pointcloud.readers import ply
    from tests.support.blender_helpers import extension_module

    session = extension_module("blender.session")
    cloud_data = np.load(cloud_path)
    ply_path = work / "cloud.ply"
    ply.write_ply(str(ply_path), cloud_data["centres"], cloud_data["normals"])
    centres = cloud_data["centres"]
    scene, cloud, _ = frame_time.build(bpy, ply_path, centres)
    cloud.splat_tracer.closed = True  # as frame_time.py
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = width, height, 100

    def one(samples: int) -> list:
        c0 = time.process_time()  # here, not in frame(): the older tree's frame() has no CPU time
        f = frame_time.frame(bpy, scene, "SPLAT_TRACER", samples, work / "frame.exr", session)
        return [f["seconds"], f["stats"]["render_seconds"], time.process_time() - c0]

    one(1)  # warm-up: first-frame costs (loading, caches) are not the comparison
    ones = [one(1) for _ in range(3)]
    print("PROBE " + json.dumps({"1": sorted(ones)[1], "16": one(16)}), flush=True)


def before_tree(commit: str, build: bool) -> Path | None:
    tree = ROOT / "build" / f"before_{commit}"
    core = tree / "splat_tracer" / "_core.abi3.so"
    if core.is_file():
        return tree
    if not build:
        return None
    tree.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", commit], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    print(f"before_after: building the core of {commit} in {tree.relative_to(ROOT)}", flush=True)
    subprocess.run([sys.executable, "setup.py", "--quiet", "build_ext", "--inplace"], cwd=tree, check=True)
    return tree


def run_probe(tree: Path, cloud_path: Path, width: int, height: int) -> dict:
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--probe", str(tree), "--cloud",
                          str(cloud_path), "--size", f"{width}x{height}"], cwd=tree, capture_output=True, text=True)
    for line in out.stdout.splitlines():
        if line.startswith("PROBE "):
            return json.loads(line[6:])
    raise SystemExit(f"before_after: the probe in {tree} failed:\n{out.stdout[-2000:]}\n{out.stderr[-2000:]}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--commit", default="e8ba060", help="the commit before the change (default: e8ba060)")
    ap.add_argument("--before", default=None, help="a tree of that commit with its core built")
    ap.add_argument("--rounds", type=int, default=None, help="rounds (default 7; 2 with --quick)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--output", default=str(HERE / "results"))
    ap.add_argument("--probe", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--cloud", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--size", default="640x480", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    width, height = map(int, args.size.split("x"))
    if args.probe:
        probe(Path(args.probe).resolve(), Path(args.cloud), width, height)
        return 0
    if args.quick:
        width, height = 320, 240
    rounds = args.rounds or (2 if args.quick else 7)
    before = Path(args.before).resolve() if args.before else before_tree(args.commit, build=not args.quick)
    if before is None:
        print(f"before_after: skipped (--quick builds nothing: build/before_{args.commit}/ has no core; "
              f"`make bench` builds it)")
        return 0
    import numpy as np

    from benchmarks.frame_time import bunny_cloud

    name, centres, normals = bunny_cloud()
    cloud_path = ROOT / "build" / "before_after_cloud.npz"
    cloud_path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(cloud_path, centres=centres, normals=normals)
    trees = {f"before ({args.commit})": before, "after (this tree)": ROOT}
    runs = {label: [] for label in trees}
    load = [os.getloadavg()[0]]
    for i in range(rounds):
        order = list(trees) if i % 2 == 0 else list(trees)[::-1]
        for label in order:
            r = run_probe(trees[label], cloud_path, width, height)
            runs[label].append(r)
            print(f"round {i + 1}: {label:22s} 1 spp {r['1'][0]:.3f} s ({r['1'][1]:.3f} rendering, CPU {r['1'][2]:.2f}), "
                  f"16 spp {r['16'][0]:.2f} s ({r['16'][1]:.2f}, CPU {r['16'][2]:.2f})", flush=True)
        load.append(os.getloadavg()[0])

    def summary(got: list, spp: str, which: int) -> dict:
        values = [g[spp][which] for g in got]
        return {"median": statistics.median(values), "low": min(values), "high": max(values), "runs": values}

    report = {"commit": args.commit, "cloud": name, "splats": len(centres), "size": [width, height],
              "rounds": rounds, "load_average": load,
              "trees": {label: {f"{spp} spp {kind}": summary(got, spp, which)
                                for spp in ("1", "16")
                                for which, kind in ((0, "frame"), (1, "rendering"), (2, "CPU"))}
                        for label, got in runs.items()}}
    out_dir = Path(args.output)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "before_after.json").write_text(json.dumps(report, indent=1))
    write_report(report, out_dir)
    return 0


def write_report(report: dict, out_dir: Path) -> None:
    commit, name, splats, load = report["commit"], report["cloud"], report["splats"], report["load_average"]
    (width, height), rounds = report["size"], report["rounds"]
    lines = [f"# An untextured scene before and after the shader-node evaluator ({commit} against this tree)",
             "", f"benchmarks/frame_time.py's scene ({name}, {splats:,} splats, on a floor; one sun, a grey world), "
             f"{width}x{height}, Splat Tracer; {rounds} rounds, one Blender process per tree and round, the trees "
             "in alternating order; a round's 1-sample figure is the median of 3 frames after a warm-up. "
             f"Median over the rounds (lowest to highest); CPU: the process's CPU time for the frame (all threads), "
             "which the load stretches far less than the wall time. Load average of the 2-core machine during the run: "
             f"{min(load):.1f} to {max(load):.1f}.", "",
             "| tree | 1 spp frame (s) | 1 spp rendering (s) | 1 spp CPU (s) | 16 spp frame (s) | "
             "16 spp rendering (s) | 16 spp CPU (s) |", "|---|---:|---:|---:|---:|---:|---:|"]
    for label, s in report["trees"].items():
        cells = [f"{s[k]['median']:.3f} ({s[k]['low']:.3f}–{s[k]['high']:.3f})"
                 for k in KEYS]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    b, a = report["trees"].values()
    lines += ["", "After against before (medians): " + ", ".join(
        f"{k} {100 * (a[k]['median'] / b[k]['median'] - 1):+.1f} %"
        for k in KEYS) + "."]
    lines += ["", "After against before (the lowest of the rounds, where the load added least): " + ", ".join(
        f"{k} {100 * (a[k]['low'] / b[k]['low'] - 1):+.1f} %"
        for k in KEYS) + "."]
    (out_dir / "before_after.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
