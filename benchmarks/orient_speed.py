"""Speed and peak memory of the normals' consistent orientation (normals.orient, PROPAGATE)
alone, on import_speed.py's terrain, without Blender.

    python -m benchmarks.orient_speed [--points N] [--mode MODE] [--root DIR]

The inputs are made once per N and cached in build/orient_bench/ (positions, the 8-nearest
neighbour table as estimate() fills it, and the terrain's true normals with a little noise
and random signs: orient() only sees an unoriented axis per point). The timed run happens
in a fresh process so that its peak RSS (reset with Linux's clear_refs just before, read
from VmHWM after) is its own: the peak minus the RSS before, over N, is what orient() adds
on top of its inputs. --mode: the orientation mode (PROPAGATE by default; AUTO adds its
range-image test, visibility and terrain rule). --root times the splat_tracer package under DIR instead of this
checkout's: another version, for a before/after comparison (e.g. `git archive <commit>
splat_tracer | tar -x -C DIR`, plus a built _core.abi3.so copied into DIR/splat_tracer).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

NOISE = 0.02  # radians-ish: the spread of PCA normals about the truth on a clean scan


def inputs(n: int) -> Path:
    folder = ROOT / "build" / "orient_bench" / str(n)
    if (folder / "graph.npy").is_file():
        return folder
    from benchmarks.import_speed import terrain
    from splat_tracer.pointcloud import normals
    from splat_tracer.pointcloud.neighbours import PointIndex

    pos, nrm, _ = terrain(n)
    rng = np.random.default_rng(1)
    nrm = nrm + NOISE * rng.normal(size=nrm.shape)
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm *= rng.choice([-1.0, 1.0], (n, 1))
    tree = PointIndex(pos)  # the importer's neighbour search: the table estimate() fills
    graph = np.empty((n, normals.GRAPH_K + 1), np.int32)
    graph[tree.order, 0] = tree.order
    graph[tree.order, 1:] = tree.knn(tree.order, normals.GRAPH_K)[1]
    folder.mkdir(parents=True, exist_ok=True)
    np.save(folder / "pos.npy", pos)
    np.save(folder / "nrm.npy", nrm)
    np.save(folder / "graph.npy", graph)
    return folder


def run(folder: Path, mode: str = "PROPAGATE") -> dict:
    from splat_tracer.pointcloud import normals

    from benchmarks.import_speed import _peak_since, _start_peak

    pos, nrm, graph = (np.load(folder / f"{name}.npy") for name in ("pos", "nrm", "graph"))
    base = _start_peak()
    steps = []
    t0 = time.perf_counter()

    def progress(fraction, message):
        if not steps or steps[-1][1] != message:
            steps.append((time.perf_counter() - t0, message))

    # AUTO's range-image test looks from the file's origin: the terrain's (0, 0, 0) corner
    extra = {"viewpoint": np.zeros(3)} if mode == "AUTO" else {}  # (a --root before AUTO has no viewpoint)
    result = normals.orient(pos, nrm, mode, graph=graph, progress=progress, **extra)
    seconds = time.perf_counter() - t0
    return {"points": len(pos), "seconds": seconds, "peak_bytes_per_point": _peak_since(base) / len(pos),
            "upward": float((result.normals[:, 2] > 0).mean()), "ambiguous": int(result.ambiguous.sum()),
            "components": result.components, "mode": result.mode, "steps": steps}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--mode", default="PROPAGATE", help="orientation mode (normals.MODES)")
    ap.add_argument("--root", help="directory holding the splat_tracer package to time (default: this checkout)")
    ap.add_argument("--case", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.case:
        if args.root:
            sys.path.insert(0, args.root)  # the other version's splat_tracer before this checkout's
        print(json.dumps(run(Path(args.case), args.mode)), flush=True)
        return 0
    folder = inputs(args.points)
    load = os.getloadavg()
    cmd = [sys.executable, "-m", "benchmarks.orient_speed", "--case", str(folder), "--mode", args.mode]
    cmd += ["--root", args.root] if args.root else []
    out = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True, cwd=ROOT)
                     .stdout.strip().splitlines()[-1])
    out["load_before"] = load
    out["load_after"] = os.getloadavg()
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
