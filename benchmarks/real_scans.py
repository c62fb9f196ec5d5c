"""Real captures, each imported with the default options through the add-on's own pipeline
(splat_tracer.pointcloud.importer.load) and rendered by the full and the general method
beside Cycles (the points as spheres shaded with the point normals), in one run, from one
camera per scan.

    python -m benchmarks.real_scans [--output DIR] [--scans DIR]   (`make bench`)
    python -m benchmarks.real_scans --quick                         (`make bench-quick`: bun000 only, core only)

The scans (SCANS below, and docs/results.md#real-scans) are public test data of well-known
projects, fetched once into a cache: --scans, else $SPLAT_TRACER_SCANS, else
~/.cache/splat_tracer/real_scans. A missing scan is skipped and named with where to get it;
an empty cache is not a failure. Nothing in the tests needs the cache.

Every renderer draws the same frame: 1 sample at the pixel centre, lit only by a point lamp
at the camera (no world light, no bounces; a headlight that is a real lamp, so a normal
facing away from the camera renders black, as it would under any lamp in Blender).

Scores, every scan:
- facing away: the share of covered pixels whose shading normal (the Normal pass) points
  away from the camera (n . ray direction > 0).
- near-black: the share of covered pixels darker than NEAR_BLACK times what a surface facing
  the lamp squarely at the same distance receives (the pixel's value x distance^2, divided by
  that of a calibration render of a facing surface at unit distance, per renderer).
- pinholes: uncovered regions (4-connected) of at most PINHOLE_PIXELS pixels that do not
  touch the image's border, i.e. small gaps enclosed by the surface, as a share of the
  covered pixels plus the pinholes.
Scans with a reference mesh (the Stanford bunny's range scans), besides: normal, silhouette
and depth errors against the mesh ray-cast exactly (benchmarks/truth.py, scoring.py, as in
the accuracy benchmark), and the importer's own normal error: each estimated normal against
the mesh's normal at the nearest surface point (a dense area sample of the mesh), signs
included.
Times: import (importer.load, median of --repeat runs, with the range), render (one run).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

HERE = Path(__file__).resolve().parent
DEFAULT_CACHE = Path.home() / ".cache" / "splat_tracer" / "real_scans"
CACHE_ENV = "SPLAT_TRACER_SCANS"

# A pixel is near-black below this share of the light a surface facing the lamp squarely
# receives at the same distance: the Lambert term of a normal 87 degrees off the light, or
# a face turned away. 5 % of the face-on value is 0.05 x 0.8 albedo = 0.04 linear, about
# 56/255 after the sRGB transform at exposure 1 -- visibly black beside a lit surface.
NEAR_BLACK = 0.05
# Pinholes: an uncovered region enclosed by covered pixels and no larger than this (a 3 x 3
# hole, a slit of 9) is a gap between splats; a larger enclosed region can be a real hole
# in the scan or background seen through the object, and is left to the silhouette error.
PINHOLE_PIXELS = 9

PCL = ("PointCloudLibrary/pcl", "1fdb03883eab28f642e938d9bf4d317903212cb4",
       "PCL's test data (PCL: BSD-3-Clause)")
STANFORD = ("Minisal/ICP", "ceb04586e8eebd5e1d884237b9e6f95d92e3ecc8",
            "Stanford 3D Scanning Repository's raw range scans (Cyberware laser), copied in that repository; "
            "Stanford's terms: free for research, cite the repository")


@dataclass(frozen=True)
class Scan:
    name: str        # the row's name
    files: tuple     # the cached file names it needs
    repo: str
    commit: str
    paths: tuple     # each file's path in the repository
    what: str        # what it is, and its licence
    kind: str        # "reference" (a mesh to score against), "frame" (depth/stereo), "aerial", "terrestrial"


SCANS = (
    Scan("bun000", ("bun000.ply",), STANFORD[0], STANFORD[1], ("data/bun000.ply",),
         "bunny, one laser range scan (40,256 points, ASCII PLY with a range_grid element); " + STANFORD[2],
         "reference"),
    Scan("bun000+bun045", ("bun000.ply", "bun045.ply"), STANFORD[0], STANFORD[1],
         ("data/bun000.ply", "data/bun045.ply"),
         "two scans registered by Stanford's bun.conf pose (overlapping layers); " + STANFORD[2], "reference"),
    Scan("table_scene_mug_stereo_textured", ("table_scene_mug_stereo_textured.pcd",), *PCL[:2],
         ("test/table_scene_mug_stereo_textured.pcd",), "stereo frame, organised 640x480; " + PCL[2], "frame"),
    Scan("milk_cartoon_all_small_clorox", ("milk_cartoon_all_small_clorox.pcd",), *PCL[:2],
         ("test/milk_cartoon_all_small_clorox.pcd",), "Kinect depth frame, organised 640x480; " + PCL[2], "frame"),
    Scan("office1", ("office1.pcd",), *PCL[:2], ("test/office1.pcd",),
         "Kinect depth frame of an office (4-5 m), organised 640x480; " + PCL[2], "frame"),
    Scan("five_people", ("five_people.pcd",), *PCL[:2], ("test/five_people.pcd",),
         "Kinect depth frame of five people, organised 640x480; " + PCL[2], "frame"),
    Scan("stereo_left", ("stereo_left.pcd",), *PCL[:2], ("test/stereo_left.pcd",),
         "a stereo pair's left image: rgba only, no x y z (an importer must refuse it by name); " + PCL[2],
         "frame"),
    Scan("autzen_trim", ("autzen_trim.las",), "PDAL/PDAL", "ccf0ab7046072f68cab78734e90d0d3149f3af10",
         ("test/data/las/autzen_trim.las",), "airborne LiDAR, 110,000 points, LAS 1.2; PDAL's test data (BSD)",
         "aerial"),
    Scan("pumpA", ("pumpAVisualReferenceImage.e57",), "davidcaron/pye57", "b8d20999f3037c580bf1fe1dcb239c50a8f764ad",
         ("tests/test_data/pumpAVisualReferenceImage.e57",),
         "terrestrial scan with its scanner pose, E57; pye57's test data (MIT), from libE57's samples",
         "terrestrial"),
)
QUICK_SCANS = ("bun000",)

# Stanford's bun.conf: "bmesh bun045.ply -0.0520211 -0.000383981 -0.0109223 0.00548449
# -0.294635 -0.0038555 0.955586" (translation, then quaternion x y z w). Checked against the
# reconstructed mesh (benchmarks/meshes.SHARED_MESHES/stanford-bunny.obj, in bun000's frame):
# applied as p -> p R + t (R from the quaternion; the row-vector form, i.e. the quaternion's
# inverse rotation) bun045's points lie a median 0.146 mm from the mesh, as bun000's
# (identity) do, 0.149 mm; as R p + t they lie 28 mm off. No ICP refinement was needed.
BUN045_T = np.array([-0.0520211, -0.000383981, -0.0109223])
BUN045_Q = (0.00548449, -0.294635, -0.0038555, 0.955586)
REFERENCE_MESH = "stanford-bunny.obj"
REFERENCE_SAMPLES = 1_000_000  # mesh points for the nearest-surface normal: 0.1 mm apart on the bunny

# The lamp at the camera (Blender's watts); the scores divide by a calibration render, so its
# power only has to keep values far above float noise and far below overflow.
LAMP_POWER = 100.0
# A second light for the core's renders: the same lamp moved 30 degrees about the view's up
# axis around the bulk's centre, casting shadows. A lamp at the camera hides what the issue
# saw on depth frames oriented away from their sensor (their discs shadowing each other
# under any other light); this one shows it, with the scene's real shadows beside it (Cycles
# renders it too, so the real shadows have a reference).
OFFSET_DEGREES = 30.0


def source_url(scan: Scan, path: str) -> str:
    return f"https://raw.githubusercontent.com/{scan.repo}/{scan.commit}/{path}"


def cache_dir(flag: Optional[str] = None) -> Path:
    return Path(flag or os.environ.get(CACHE_ENV) or DEFAULT_CACHE).expanduser()


# --------------------------------------------------------------------------------------
# Metrics on images (top row first); tests/render/test_real_scan_metrics.py checks them.

def facing_away_share(covered: np.ndarray, normal: np.ndarray, directions: np.ndarray) -> float:
    """Share (0..1) of covered pixels whose normal points away from the camera: n . d > 0 for
    the pixel's ray direction d. covered (H,W) bool, normal (H,W,3), directions (H,W,3)."""
    if not covered.any():
        return float("nan")
    dots = np.einsum("ijk,ijk->ij", normal.astype(np.float64), directions.astype(np.float64))
    return float((dots[covered] > 0).mean())


def near_black_share(covered: np.ndarray, shade: np.ndarray, threshold: float = NEAR_BLACK) -> float:
    """Share of covered pixels whose shade (relative to a surface facing the lamp squarely,
    see relative_shade) is below `threshold`."""
    if not covered.any():
        return float("nan")
    return float((shade[covered] < threshold).mean())


def relative_shade(luminance: np.ndarray, distance: np.ndarray, calibration: float) -> np.ndarray:
    """A pixel lit by a lamp at the camera, as a share of what a surface facing the lamp
    squarely at the same distance receives: luminance x distance^2 / calibration, where
    calibration is the luminance of such a surface at unit distance."""
    return luminance * np.square(distance) / calibration


def pinholes(covered: np.ndarray, max_pixels: int = PINHOLE_PIXELS) -> np.ndarray:
    """(H,W) bool: the pinholes, uncovered 4-connected regions of at most `max_pixels` pixels
    that do not touch the image's border (see the module's text)."""
    from scipy import ndimage

    c = np.asarray(covered, bool)
    labels, count = ndimage.label(~c)  # 4-connected: the dual of an 8-connected covered ring
    if count == 0:
        return np.zeros_like(c)
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    small = sizes <= max_pixels
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    small[border] = False
    small[0] = False  # label 0: the covered pixels
    return small[labels]


def pinhole_share(covered: np.ndarray, max_pixels: int = PINHOLE_PIXELS) -> float:
    """Pinholes as a share of the covered pixels plus the pinholes."""
    holes = int(pinholes(covered, max_pixels).sum())
    total = int(np.asarray(covered, bool).sum()) + holes
    return float(holes / total) if total else float("nan")


# --------------------------------------------------------------------------------------
# Scans: reading, the camera.

def bun045_rotation() -> np.ndarray:
    """bun045's rotation matrix (BUN045_Q, x y z w, as bun.conf writes it)."""
    from splat_tracer.util.matrices import quaternion_matrices

    x, y, z, w = BUN045_Q
    return quaternion_matrices(np.array([[w, x, y, z]]))[0]


def import_path(scan: Scan, cache: Path, tmp: Path) -> Path:
    """The file importer.load reads for the scan: the cached file, or for the registered pair
    a PLY of both scans' points in bun000's frame."""
    if scan.name != "bun000+bun045":
        return cache / scan.files[0]
    from splat_tracer.pointcloud.readers import ply, read_cloud

    a = read_cloud(str(cache / "bun000.ply")).positions
    b = read_cloud(str(cache / "bun045.ply")).positions @ bun045_rotation() + BUN045_T
    path = tmp / "bun000+bun045.ply"
    ply.write_ply(str(path), np.vstack([a, b]), None)  # positions only: the importer estimates the normals
    return path


def view_for(scan: Scan, prepared, world: np.ndarray, width: int, height: int) -> dict:
    """Camera.look_at arguments, in the file's (world) coordinates (`world`: the imported
    points there)."""
    from benchmarks import meshes

    lo, hi = np.percentile(world, 1, axis=0), np.percentile(world, 99, axis=0)
    aspect = width / height
    if scan.kind == "reference":
        # The scanner looked at the bunny's front (+z); the pair from between its two views.
        direction = np.array([0.0, 0.0, -1.0])
        if scan.name == "bun000+bun045":
            direction = direction + direction @ bun045_rotation()
        return meshes.camera_view(world, width, height, direction=direction, fov_y=30.0)
    if scan.kind == "frame":
        # Organised depth/stereo frames are in the sensor's frame (VIEWPOINT at the origin):
        # it looks along +z with +y down the image, as the data show (every z > 0).
        far = float(hi[2]) * 2
        return dict(eye=np.zeros(3), target=np.array([0.0, 0.0, 1.0]), up=np.array([0.0, -1.0, 0.0]),
                    fov_y=45.0, aspect=aspect, near=0.05, far=far)
    if scan.kind == "aerial":
        # From above, the whole tile in view (a perspective camera high enough that the
        # obliquity at the edges stays under 25 degrees).
        centre = (lo + hi) / 2
        half = max((hi[0] - lo[0]) / 2 / aspect, (hi[1] - lo[1]) / 2) * 1.05
        fov = 40.0
        height_above = half / np.tan(np.radians(fov / 2))
        eye = np.array([centre[0], centre[1], hi[2] + height_above])
        return dict(eye=eye, target=np.array([centre[0], centre[1], lo[2]]), up=np.array([0.0, 1.0, 0.0]),
                    fov_y=fov, aspect=aspect, near=1.0, far=height_above * 4)
    # Terrestrial: at the scanner's position (the file's pose), looking at the bulk.
    scanners = prepared.cloud.scanners
    eye = np.median(scanners, axis=0) if scanners is not None else np.zeros(3)
    target = (lo + hi) / 2
    size = float(np.linalg.norm(hi - lo))
    return dict(eye=eye, target=target, up=np.array([0.0, 0.0, 1.0]), fov_y=70.0, aspect=aspect,
                near=size * 1e-3, far=size * 10)


# --------------------------------------------------------------------------------------
# Rendering.

# The calibration renders' camera: at the origin looking down -z, a narrow view of the
# facing surface one unit away.
CALIBRATION_VIEW = dict(eye=np.zeros(3), target=np.array([0.0, 0.0, -1.0]), up=np.array([0.0, 1.0, 0.0]),
                        fov_y=10.0, aspect=1.0, near=0.01, far=10.0)
CORE_SETTINGS = dict(samples=1, pixel_filter="BOX", filter_width=0.01, max_bounces=0, diffuse_bounces=0,
                     glossy_bounces=0, transmission_bounces=0)


def offset_lamp(view: dict, centre: np.ndarray) -> np.ndarray:
    """The camera's position turned OFFSET_DEGREES about the view's up axis around `centre`."""
    up = np.asarray(view["up"], np.float64)
    up /= np.linalg.norm(up)
    v = np.asarray(view["eye"], np.float64) - centre
    a = np.radians(OFFSET_DEGREES)
    # Rodrigues' rotation of v about up
    turned = v * np.cos(a) + np.cross(up, v) * np.sin(a) + up * (up @ v) * (1 - np.cos(a))
    return centre + turned


def core_frame(prepared, view: dict, width: int, height: int, method: str, lamp=None) -> dict:
    """The prepared cloud through the core's scene renderer with the lamp at the camera, or
    at `lamp` (world coordinates) casting shadows."""
    from splat_tracer.render.camera import Camera
    from splat_tracer.render.method import Method
    from splat_tracer.render.scene import Instance, RenderScene
    from splat_tracer.render.shading import Light, RenderSettings, World
    from splat_tracer.render.splats import SplatCloud

    origin = prepared.origin
    cam = Camera.look_at(**{**view, "eye": view["eye"] - origin, "target": view["target"] - origin})
    t0 = time.perf_counter()
    cloud = SplatCloud(prepared.local, prepared.cloud.normals, prepared.radii, closed=prepared.hood.closed_guess)
    light = (Light("POINT", power=LAMP_POWER, position=tuple(cam.position), cast_shadow=False) if lamp is None else
             Light("POINT", power=LAMP_POWER, position=tuple(np.asarray(lamp, np.float64) - origin), cast_shadow=True))
    scene = RenderScene([Instance(cloud)], [light],
                        World(colour=(0.0, 0.0, 0.0), transparent=True))
    out = scene.render(cam, width, height, RenderSettings(**CORE_SETTINGS), Method.preset(method),
                       passes=("Depth", "Normal"))
    seconds = time.perf_counter() - t0
    p = out.passes
    return {"seconds": seconds, "rgba": p["Combined"], "depth": p["Depth"].astype(np.float64),
            "normal": p["Normal"]}


def core_calibration() -> float:
    """The luminance the core gives a surface facing the lamp squarely at unit distance: a
    disc of radius 0.5 at distance 1 in front of the camera, facing it."""
    from types import SimpleNamespace

    disc = SimpleNamespace(origin=np.zeros(3), local=np.array([[0.0, 0.0, -1.0]], np.float32),
                           radii=np.array([0.5], np.float32),
                           cloud=SimpleNamespace(normals=np.array([[0.0, 0.0, 1.0]], np.float32)),
                           hood=SimpleNamespace(closed_guess=False))
    frame = core_frame(disc, CALIBRATION_VIEW, 9, 9, "GENERAL")
    return float(frame["rgba"][4, 4, :3].mean())


def blender_frame(workdir: Path, name: str, world_points, normals, radii, view, width, height,
                  closed: bool, lamp=None) -> dict:
    """Cycles on the same points as spheres (the importer's Mesh to Points) shaded with the
    point normals, lit by the same lamp at the camera (blender_runs.render)."""
    from benchmarks import blender_runs
    from splat_tracer.pointcloud.readers import ply

    path = workdir / f"{name}.ply"
    # Grey points (the Splat Cloud material needs colours; 0.8 as the core's default material).
    grey = np.full((len(world_points), 3), 0.8, np.float32)
    ply.write_ply(str(path), world_points, normals, colours=grey, radii=radii)
    out = blender_runs.render("CYCLES", path, view, width, height, workdir, closed, lamp_power=LAMP_POWER,
                              point_normals=True, lamp_position=lamp)
    h = height
    return {"seconds": out["seconds"], "rgba": out["rgba"], "depth": out["depth"].reshape(h, width),
            "normal": out["normal"].reshape(h, width, 3)}


def cycles_calibration(workdir: Path) -> float:
    """The luminance Cycles gives a sphere shaded with a normal facing the lamp, at unit
    distance (its front at 1). A second sphere, out of view, because the importer needs two
    points."""
    out = blender_frame(workdir, "calibration", np.array([[0.0, 0.0, -1.3], [5.0, 5.0, -5.0]]),
                        np.array([[0.0, 0.0, 1.0]] * 2), np.array([0.3, 0.3]), CALIBRATION_VIEW, 9, 9, False)
    return float(out["rgba"][4, 4, :3].mean())


def frame_scores(frame: dict, directions: np.ndarray, forward: np.ndarray, calibration: float) -> dict:
    """The scores every scan gets (see the module's text); directions (H,W,3) unit rays."""
    covered = frame["depth"] < 1e9
    cos_axis = directions @ forward  # planar depth -> distance along the ray
    distance = np.where(covered, frame["depth"], 0.0) / cos_axis
    shade = relative_shade(frame["rgba"][..., :3].astype(np.float64).mean(axis=2), distance, calibration)
    frame["shade"], frame["covered"] = shade, covered
    return {"covered_px": int(covered.sum()),
            "facing_away_pct": 100 * facing_away_share(covered, frame["normal"], directions),
            "near_black_pct": 100 * near_black_share(covered, shade),
            "pinholes_pct": 100 * pinhole_share(covered)}


# --------------------------------------------------------------------------------------
# The run.

def reference_mesh():
    from benchmarks import meshes

    path = meshes.SHARED_MESHES / REFERENCE_MESH
    return meshes.read_obj(path) if path.is_file() else None


def importer_normal_error(prepared, world, vertices, triangles) -> dict:
    """Each imported normal (at `world`: the imported points in the file's coordinates) against
    the mesh's normal at the nearest surface point: mean angle (signs included: a flipped
    normal counts 180 degrees) and the share flipped."""
    from scipy.spatial import cKDTree

    from benchmarks import meshes

    samples, sample_normals = meshes.area_samples(vertices, triangles, REFERENCE_SAMPLES)
    _, nearest = cKDTree(samples).query(world, workers=-1)
    n = prepared.cloud.normals.astype(np.float64)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    cos = np.clip(np.einsum("ij,ij->i", n, sample_normals[nearest]), -1, 1)
    return {"import_normal_deg": float(np.degrees(np.arccos(cos)).mean()),
            "import_flipped_pct": float(100 * (cos < 0).mean())}


def run_scan(scan: Scan, args, cache: Path, tmp: Path, mesh, calibrations: dict, images: dict) -> dict:
    from splat_tracer.pointcloud import importer
    from splat_tracer.pointcloud.cloud import CloudFileError
    from splat_tracer.render.camera import Camera

    row = {"scan": scan.name, "kind": scan.kind}
    path = import_path(scan, cache, tmp)
    seconds, prepared = [], None
    try:
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            prepared = importer.load(str(path))
            seconds.append(time.perf_counter() - t0)
    except CloudFileError as e:
        row["error"] = str(e).replace(str(path), path.name)
        print(f"{scan.name:32s} not imported: {row['error']}", flush=True)
        return row
    row.update(points=len(prepared.local), import_s=statistics.median(seconds), import_min_s=min(seconds),
               import_max_s=max(seconds), import_runs=len(seconds), closed_guess=bool(prepared.hood.closed_guess),
               normals_estimated=bool(prepared.normals_estimated), oriented=prepared.normals_oriented,
               notes=prepared.notes(importer.ImportOptions().k))
    normals = ("estimated, oriented " + prepared.normals_oriented) if prepared.normals_estimated else "from the file"
    print(f"{scan.name:32s} {len(prepared.local):8,d} points, import {row['import_s']:.2f} s "
          f"(median of {len(seconds)}), normals {normals}", flush=True)
    width, height = args.size
    world_points = prepared.local.astype(np.float64) + prepared.origin
    view = view_for(scan, prepared, world_points, width, height)
    cam = Camera.look_at(**view)
    o, d = cam.rays(width, height)
    d64 = d.astype(np.float64)
    d64 /= np.linalg.norm(d64, axis=1, keepdims=True)
    directions = d64.reshape(height, width, 3)
    # The import's orientation, before any shading turns a back hit towards the ray: the share
    # of all imported normals on the camera's side (the camera is at the sensor for the
    # depth frames and the E57, above the LAS).
    towards = np.asarray(cam.position, np.float64) - world_points
    row["facing_camera_pct"] = float(100 * (np.einsum("ij,ij->i", prepared.cloud.normals, towards) > 0).mean())
    truth = None
    if scan.kind == "reference" and mesh is not None:
        from benchmarks import meshes, truth as truth_mod

        vertices, triangles = mesh
        truth = truth_mod.cast(vertices, triangles, meshes.corner_normals(vertices, triangles), o.astype(np.float64),
                               d64, cam.position, cam.forward)
        row.update(importer_normal_error(prepared, world_points, vertices, triangles))
        row["raw_normals"] = "from the file" if not prepared.normals_estimated else "none in the file"
    frames, offset = {}, {}
    renderers = [("full", "FULL"), ("general", "GENERAL")]
    lamp = offset_lamp(view, np.median(world_points, axis=0))
    for label, method in renderers:
        frames[label] = core_frame(prepared, view, width, height, method)
        offset[label] = core_frame(prepared, view, width, height, method, lamp=lamp)
    if args.cycles:
        if "cycles" not in calibrations:
            calibrations["cycles"] = cycles_calibration(tmp)
        frames["cycles"] = blender_frame(tmp, scan.name, world_points, prepared.cloud.normals, prepared.radii, view, width,
                                         height, bool(prepared.hood.closed_guess))
        offset["cycles"] = blender_frame(tmp, scan.name, world_points, prepared.cloud.normals, prepared.radii, view, width,
                                         height, bool(prepared.hood.closed_guess), lamp=lamp)
    row["renderers"] = {}
    for label, frame in frames.items():
        s = frame_scores(frame, directions, cam.forward, calibrations["cycles" if label == "cycles" else "core"])
        s["render_s"] = frame["seconds"]
        if truth is not None:
            from benchmarks import scoring

            s.update(scoring.score(truth, frame["covered"].ravel(), frame["depth"].ravel(),
                                   frame["normal"].reshape(-1, 3), d64, float(np.median(prepared.radii))))
        if label in offset:  # the offset lamp: distances from it, not from the camera
            f = offset[label]
            covered = f["depth"] < 1e9
            along = np.where(covered, f["depth"], 0.0) / (directions @ cam.forward)
            hit = np.asarray(cam.position, np.float64) + directions * along[..., None]
            to_lamp = np.linalg.norm(hit - lamp, axis=-1)
            shade = relative_shade(f["rgba"][..., :3].astype(np.float64).mean(axis=2), to_lamp,
                                   calibrations["cycles" if label == "cycles" else "core"])
            s["near_black_offset_pct"] = 100 * near_black_share(covered, shade)
        row["renderers"][label] = s
        print(f"    {label:8s} facing away {s['facing_away_pct']:5.1f} %, near-black {s['near_black_pct']:5.1f} %, "
              f"pinholes {s['pinholes_pct']:5.2f} %"
              + (f", near-black with the lamp {OFFSET_DEGREES:g} deg off {s['near_black_offset_pct']:5.1f} %"
                 if "near_black_offset_pct" in s else "")
              + (f", normal {s['normal_mean_deg']:.2f} deg, silhouette {s['silhouette_pct']:.2f} %, "
                 f"depth {100 * s['depth_mean_rel']:.3f} %" if truth is not None else "")
              + f", render {s['render_s']:.2f} s", flush=True)
    images[scan.name] = {label: (f["shade"], f["covered"]) for label, f in frames.items()}
    return row


def missing(scan: Scan, cache: Path) -> list:
    return [(f, p) for f, p in zip(scan.files, scan.paths) if not (cache / f).is_file()]


def fmt(v, digits=1, scale=1.0):
    return "-" if v is None or (isinstance(v, float) and np.isnan(v)) else f"{v * scale:.{digits}f}"


def markdown(rows: list, meta: dict) -> str:
    lines = [f"Measured at commit {meta['commit']} on {meta['cpus']} cores: {meta['width']}x{meta['height']}, "
             f"1 sample at the pixel centre, a point lamp at the camera; Cycles {meta.get('cycles', 'not run')}. "
             f"Import: median of {meta['repeat']} runs (range). Render: one run each (Cycles' includes its "
             f"scene sync and BVH build). Near-black: below {NEAR_BLACK:g} x a facing surface's light; "
             f"pinholes: enclosed uncovered regions of at most {PINHOLE_PIXELS} px. The core also renders with the lamp "
             f"turned {OFFSET_DEGREES:g} deg about the view's up axis around the bulk's centre, casting shadows, and "
             f"so does Cycles (that near-black share counts the scene's real shadows too). Total {meta['seconds']:.0f} s.",
             "",
             "| scan | points | import s | renderer | facing away % | near-black % | near-black, lamp 30° off % | "
             "pinholes % | normal error deg | silhouette % | depth error % | render s |",
             "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        if "error" in r or "missing" in r:
            lines.append(f"| {r['scan']} | - | - | {r.get('error') or 'not in the cache'} | | | | | | | | |")
            continue
        imp = f"{r['import_s']:.2f} ({r['import_min_s']:.2f}-{r['import_max_s']:.2f})"
        for i, (label, s) in enumerate(r["renderers"].items()):
            name = {"full": "full", "general": "general", "cycles": "Cycles spheres"}[label]
            lines.append(f"| {r['scan'] if i == 0 else ''} | {r['points'] if i == 0 else ''} | {imp if i == 0 else ''} "
                         f"| {name} | {fmt(s['facing_away_pct'])} | {fmt(s['near_black_pct'])} | "
                         f"{fmt(s.get('near_black_offset_pct'))} | "
                         f"{fmt(s['pinholes_pct'], 2)} | {fmt(s.get('normal_mean_deg'), 2)} | "
                         f"{fmt(s.get('silhouette_pct'), 2)} | {fmt(s.get('depth_mean_rel'), 3, 100)} | "
                         f"{s['render_s']:.2f} |")
    oriented = [r for r in rows if "facing_camera_pct" in r]
    if oriented:
        lines += ["", "The import's orientation: the share of all imported normals on the camera's side (before "
                  "shading turns an open cloud's back hits towards the ray), and the rule that decided it:", "",
                  "| scan | facing the camera % | oriented by |", "|---|---:|---|"]
        lines += [f"| {r['scan']} | {r['facing_camera_pct']:.2f} | "
                  f"{r['oriented'] if r['normals_estimated'] else 'the file'} |" for r in oriented]
    ref = [r for r in rows if "import_normal_deg" in r]
    if ref:
        lines += ["", "The importer's own normals against the mesh's at the nearest surface point (signs included):",
                  "", "| scan | mean error deg | flipped % | the file's own normals |", "|---|---:|---:|---|"]
        lines += [f"| {r['scan']} | {r['import_normal_deg']:.2f} | {r['import_flipped_pct']:.2f} | {r['raw_normals']} |"
                  for r in ref]
    return "\n".join(lines) + "\n"


def save_images(images: dict, names, out_dir: Path) -> list:
    """For each scan: the full method beside Cycles (beside the general method when Cycles did
    not run), the lit frame as rendered (relative shade, 1 = a surface facing the lamp), the
    background in blue-grey so that pinholes show."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    for name in names:
        if name not in images:
            continue
        frames = images[name]
        right = "cycles" if "cycles" in frames else "general"
        panels = []
        for label in ("full", right):
            shade, covered = frames[label]
            rgb = np.repeat(np.clip(shade, 0, 1)[..., None] ** (1 / 2.2), 3, axis=2)
            rgb[~covered] = (0.25, 0.3, 0.45)
            panels.append(rgb)
        gap = np.ones((panels[0].shape[0], 4, 3))
        path = out_dir / f"real_scans_{name}.png"
        plt.imsave(path, np.concatenate([panels[0], gap, panels[1]], axis=1))
        written.append(path)
    return written


def git_commit() -> str:
    import subprocess

    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE.parent, capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


IMAGE_SCANS = ("bun000+bun045", "milk_cartoon_all_small_clorox", "pumpA")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="bun000 only, 160x120, core only, one import")
    ap.add_argument("--output", default=None, help="where real_scans.md/.json and the images go (default: "
                    "benchmarks/results; with --quick, build/bench-quick, so a quick run never overwrites the docs' "
                    "figures)")
    ap.add_argument("--scans", default=None, help=f"the cache (default: ${CACHE_ENV}, else {DEFAULT_CACHE})")
    ap.add_argument("--no-cycles", dest="cycles", action="store_false", help="skip Cycles")
    ap.add_argument("--repeat", type=int, default=None, help="imports per scan (default 3, quick 1)")
    args = ap.parse_args(argv)
    args.size = (160, 120) if args.quick else (320, 240)
    args.repeat = args.repeat or (1 if args.quick else 3)
    if args.quick:
        args.cycles = False
    cache = cache_dir(args.scans)
    scans = [s for s in SCANS if not args.quick or s.name in QUICK_SCANS]
    t_start = time.perf_counter()
    absent = [(s, missing(s, cache)) for s in scans]
    absent = [(s, m) for s, m in absent if m]
    if absent:
        print(f"real_scans: {len(absent)} of {len(scans)} scans are not in {cache} (skipped); fetch each file once, "
              f"e.g. curl -L --create-dirs -o {cache}/FILE URL:")
        for s, m in absent:
            for f, p in m:
                print(f"  {f}: github.com/{s.repo} commit {s.commit}, {p}\n    {source_url(s, p)}")
    present = [s for s in scans if not missing(s, cache)]
    out_dir = Path(args.output or (HERE.parent / "build" / "bench-quick" if args.quick else HERE / "results"))
    rows = []
    if present:
        mesh = reference_mesh()
        if mesh is None and any(s.kind == "reference" for s in present):
            from benchmarks import meshes

            print(f"real_scans: no reference mesh at {meshes.SHARED_MESHES / REFERENCE_MESH}: "
                  "the bunny scans get no error against it")
        calibrations = {"core": core_calibration()}
        images: dict = {}
        with tempfile.TemporaryDirectory(prefix="real_scans_") as tmp:
            for s in scans:
                if s in present:
                    rows.append(run_scan(s, args, cache, Path(tmp), mesh, calibrations, images))
                else:
                    rows.append({"scan": s.name, "kind": s.kind, "missing": [f for f, _ in missing(s, cache)]})
        seconds = time.perf_counter() - t_start
        meta = {"commit": git_commit(), "cpus": os.cpu_count(), "width": args.size[0], "height": args.size[1],
                "repeat": args.repeat, "seconds": seconds, "calibrations": calibrations}
        if args.cycles:
            import bpy

            meta["cycles"] = f"{bpy.app.version_string}, 1 sample, spheres shaded with the point normals"
        out_dir.mkdir(parents=True, exist_ok=True)
        text = markdown(rows, meta)
        (out_dir / "real_scans.md").write_text(text)
        (out_dir / "real_scans.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1, default=str))
        if not args.quick:
            for p in save_images(images, IMAGE_SCANS, out_dir):
                print(f"real_scans: wrote {p}")
        print()
        print(text)
    print(f"real_scans: {len(present)} of {len(scans)} scans in {time.perf_counter() - t_start:.0f} s -> "
          f"{out_dir if present else 'nothing written'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
