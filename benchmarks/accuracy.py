"""Run time against error: every method preset, a sweep of ε and radius factor, the real
Blender render, Cycles, and the paper, scored against the true surface in one run.

    python -m benchmarks.accuracy            (`make bench`: every model, 640x480)
    python -m benchmarks.accuracy --quick    (`make bench-quick`: sphere and cube, 320x240)

Inputs: each mesh of ../shared/data/meshes (when present) and analytic shapes (sphere,
cube, torus) become two clouds: the mesh's vertices with area-weighted normals (for the
bunny, the paper's 35,947-point cloud) and N points sampled uniformly by area with the
exact face normal; then one synthetic scene per failure class of the far phase
(benchmarks/synthetic.py: crossing shells, thin parts, an open face, a notch, 10x density
changes). Radii and "closed" as the importer makes them (hole-free k-NN radii, the guess).
Truth: the source triangles ray-cast exactly (Embree) with the same pixel-centre rays.
Scores: silhouette error (pixels whose coverage disagrees; missing and extra apart),
normal angle error against the mesh's normals with creases sharper than 60 degrees kept
(meshes.corner_normals; mean, 95th percentile), mean depth error relative to the
object's size, and the share of pixels showing the wrong surface (depth off by more than
3 median splat radii: another surface, not the right one a little off).
Time: wall seconds, median of several runs (core: BVH build + render, what a frame costs;
Blender: the render call, including the EXR write), and the cores used (CPU time / wall
time; for Blender rows, of the whole import-and-render round, a lower bound).
Writes accuracy.md, accuracy.csv, accuracy.json and accuracy.png to --output.
"""
from __future__ import annotations

import argparse
import csv
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

from benchmarks import meshes, scoring, synthetic  # noqa: E402
from benchmarks import truth as truth_mod  # noqa: E402
from splat_tracer.pointcloud import spacing  # noqa: E402
from splat_tracer.pointcloud.neighbours import local_frame  # noqa: E402
from splat_tracer.pointcloud.readers import ply  # noqa: E402
from splat_tracer.render.camera import Camera  # noqa: E402
from splat_tracer.render.method import PRESETS, Method  # noqa: E402
from splat_tracer.render.splats import SplatCloud  # noqa: E402

PAPER = {"model": "stanford-bunny", "cloud": "vertices", "renderer": "paper (Beddiaf & Babahenini)",
         "method": "full", "points": 35945, "seconds": 8.5, "seconds_range": "7-10", "cores": None}


def models(quick: bool):
    analytic = [("sphere", meshes.icosphere), ("cube", meshes.box), ("torus", meshes.torus)]
    if quick:
        return [("sphere", meshes.icosphere(5)), ("cube", meshes.box(24))]
    found = [(name, fn()) for name, fn in analytic]
    if meshes.SHARED_MESHES.is_dir():
        for path in sorted(meshes.SHARED_MESHES.glob("*.obj")):
            found.append((path.stem, meshes.read_obj(path)))
    return found


def clouds(vertices, triangles, n_samples):
    yield "vertices", *meshes.vertex_cloud(vertices, triangles)
    yield f"samples {n_samples // 1000}k", *meshes.area_samples(vertices, triangles, n_samples)


def cases(quick: bool, n_samples: int):
    """(model, cloud, truth vertices, truth triangles, points, normals, view options): every
    model as both clouds (quick: the sphere's both, the cube's vertices), then the synthetic
    scene of each failure class (quick: the crossing shells)."""
    for model, (vertices, triangles) in models(quick):
        for cloud_name, points, normals in clouds(vertices, triangles, n_samples):
            if not (quick and cloud_name != "vertices" and model != "sphere"):
                yield model, cloud_name, vertices, triangles, points, normals, {}
    for sc in synthetic.scenes(n_samples):
        if not quick or sc.name == "sphere+band":
            yield sc.name, f"samples {n_samples // 1000}k", sc.vertices, sc.triangles, sc.points, sc.normals, sc.view


def configs(quick: bool):
    """(label, method, radius factor, closed override or None for the guess, hole-free radii)."""
    presets = [(p.lower().replace("_", "-"), Method.preset(p), 1.0, None, True) for p in PRESETS]
    if quick:
        return presets
    sweep = [(f"full eps={eps:g} rf={rf:g}", Method.preset("FULL", epsilon=eps), rf, None, True)
             for eps in (0.5, 1.0, 2.0) for rf in (0.8, 1.0, 1.25, 1.5) if not (eps == 1.0 and rf == 1.0)]
    sweep += [("full smooth-kernel", Method.preset("FULL", kernel="SMOOTH"), 1.0, None, True),
              ("full crease=45", Method.preset("FULL", crease_angle=45), 1.0, None, True),
              ("full crease=60", Method.preset("FULL", crease_angle=60), 1.0, None, True),
              ("full, k-NN radii", Method.preset("FULL"), 1.0, None, False),
              ("full, forced closed", Method.preset("FULL"), 1.0, True, True)]
    return presets + sweep


def timed(fn, repeats):
    walls, cpus, result = [], [], None
    for _ in range(repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        result = fn()
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    wall = statistics.median(walls)
    return wall, statistics.median(cpus) / max(wall, 1e-9), result


def run(args) -> list[dict]:
    width, height = (320, 240) if args.quick else (640, 480)
    repeats = 1 if args.quick else 3
    n_samples = 20000 if args.quick else 50000
    workdir = Path(args.output).resolve() / "work"
    workdir.mkdir(parents=True, exist_ok=True)
    rows = []
    for model, cloud_name, vertices, triangles, points, normals, view_options in cases(args.quick, n_samples):
        cnormals = meshes.corner_normals(vertices, triangles)
        origin, local = local_frame(points)
        hood = spacing.analyse(local, normals)
        covering = spacing.covering_radii(local, normals, hood.spacing)  # what the importer gives
        view = meshes.camera_view(points, width, height, **view_options)
        cam = Camera.look_at(**view)
        o, d = cam.rays(width, height)
        o64, d64 = o.astype(np.float64), d.astype(np.float64)
        d64 /= np.linalg.norm(d64, axis=1, keepdims=True)
        truth = truth_mod.cast(vertices, triangles, cnormals, o64, d64, cam.position, cam.forward)
        base = {"model": model, "cloud": cloud_name, "points": len(points), "guess_closed": hood.closed_guess,
                "width": width, "height": height}
        print(f"{model:16s} {cloud_name:12s} {len(points):7d} points, closed guess {hood.closed_guess}",
              flush=True)
        cam_local = Camera.look_at(**{**view, "eye": view["eye"] - origin, "target": view["target"] - origin})
        for label, method, rf, closed, hole_free in configs(args.quick):
            closed_flag = hood.closed_guess if closed is None else closed
            radii = covering if hole_free else hood.spacing

            def frame():
                scene = SplatCloud(local, normals, radii * rf, closed=closed_flag)
                return scene.render(cam_local, width, height, method=method)

            wall, cores, img = timed(frame, repeats)
            hit = img.rgba[..., 3].ravel() > 0.5
            s = scoring.score(truth, hit, img.depth.ravel().astype(np.float64), img.normal.reshape(-1, 3), d64,
                              float(np.median(hood.spacing)))
            rows.append({**base, "renderer": "splat_tracer core", "method": label, "epsilon": method.epsilon,
                         "radius_factor": rf, "closed": closed_flag, "seconds": wall, "cores": cores, **s})
        if args.blender:
            from benchmarks import blender_runs

            ply_path = workdir / f"{model.replace(' ', '_')}_{cloud_name.split()[0]}.ply"
            ply.write_ply(str(ply_path), points, normals, radii=covering)
            engines = [("SPLAT_TRACER", "splat_tracer in Blender (F12)", "full")]
            if args.cycles and (not args.quick or model == "sphere"):
                engines.append(("CYCLES", "Cycles, Mesh to Points spheres, 1 sample", "-"))
            for engine, name, label in engines:
                seconds = []

                def blender_frame():
                    out = blender_runs.render(engine, ply_path, view, width, height, workdir, hood.closed_guess)
                    seconds.append(out["seconds"])  # the render call alone, without import and set-up
                    return out

                _, cores, out = timed(blender_frame, repeats)
                s = scoring.score(truth, out["hit"], out["depth"], out["normal"], d64,
                                  float(np.median(hood.spacing)))
                rows.append({**base, "renderer": name, "method": label, "epsilon": None, "radius_factor": 1.0,
                             "closed": hood.closed_guess, "seconds": statistics.median(seconds), "cores": cores,
                             **s})
    rows.append({**PAPER})
    return rows


def write_reports(rows: list[dict], out_dir: Path) -> None:
    from benchmarks import report

    out_dir.mkdir(parents=True, exist_ok=True)
    keys = sorted({k for r in rows for k in r}, key=lambda k: list(rows[0]).index(k) if k in rows[0] else 99)
    with open(out_dir / "accuracy.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=keys)
        writer.writeheader()
        writer.writerows(rows)
    (out_dir / "accuracy.json").write_text(json.dumps(rows, indent=1))
    (out_dir / "accuracy.md").write_text(report.markdown(rows))
    report.plot(rows, out_dir / "accuracy.png")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="sphere and cube, 320x240, presets only (CI)")
    ap.add_argument("--output", default=str(HERE / "results"))
    ap.add_argument("--no-blender", dest="blender", action="store_false", help="core only")
    ap.add_argument("--no-cycles", dest="cycles", action="store_false", help="skip the Cycles reference")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = run(args)
    write_reports(rows, Path(args.output))
    from benchmarks import report

    print()
    print(report.summary(rows))
    print()
    print(report.per_method(rows))
    print("\nThe README's selection:\n")
    print(report.readme_table(rows))
    print(f"\naccuracy: {len(rows)} rows in {time.perf_counter() - t0:.0f} s -> {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
