"""AUTO orientation of estimated normals by the cloud's geometry, whatever its file format
(normals.orient, prepare): a range image seen from the file's origin faces it, a terrain
faces up, closed objects (with holes, in fragments) face outward by visibility.

Each case goes through a real file and the importer (importer.load), with no normals and
no viewpoint in the file. Measured when written (share of normals on the right side,
before -> after): sphere as LAS 50.7 % -> 100 %, depth frame looking +Z 0 % -> 99.5 %,
open box seen from inside 0 % -> 100 %, sphere cut into fragments 45 % -> 100 %; terrains
100 % before and after.
"""
from __future__ import annotations

import numpy as np
import pytest

from frames import box_room_frame
from geometry import fibonacci_sphere
from splat_tracer.pointcloud import importer, normals


def _write_xyz(path, p):
    np.savetxt(path, p, fmt="%.6f")
    return str(path)


def _write_las(path, p):
    import laspy

    header = laspy.LasHeader(point_format=6, version="1.4")
    header.offsets = np.floor(p.min(axis=0))
    header.scales = [1e-5, 1e-5, 1e-5]
    las = laspy.LasData(header)
    las.x, las.y, las.z = p.T
    las.write(str(path))
    return str(path)


def _write_ply(path, p):
    from plyfile import PlyData, PlyElement

    rows = np.empty(len(p), dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    rows["x"], rows["y"], rows["z"] = p.T
    PlyData([PlyElement.describe(rows, "vertex")]).write(str(path))
    return str(path)


def _load(path):
    prepared = importer.load(path)
    return prepared, prepared.local + prepared.origin, prepared.cloud.normals.astype(np.float64)


def _right(nrm, truth):
    return float((np.einsum("ij,ij->i", nrm, truth) > 0).mean())


def terrain(n, seed=0):
    """n points on a hilly height field 100 x 100 with 1.2 high hills, and its up normals."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0, 100, (n, 2))
    a, b = 2 * np.pi / 17, 2 * np.pi / 23
    z = 1.2 * np.sin(a * xy[:, 0] + seed) * np.cos(b * xy[:, 1]) + 30.0
    up = np.column_stack([-1.2 * a * np.cos(a * xy[:, 0] + seed) * np.cos(b * xy[:, 1]),
                          1.2 * b * np.sin(a * xy[:, 0] + seed) * np.sin(b * xy[:, 1]), np.ones(n)])
    return np.column_stack([xy, z]), up / np.linalg.norm(up, axis=1, keepdims=True)


def open_box(n=40000, seed=1):
    """A room without its ceiling around the origin (off centre): points on its five faces
    and their normals facing inward."""
    rng = np.random.default_rng(seed)
    lo, hi = np.array([-2.0, -3.0, -1.0]), np.array([2.5, 3.0, 1.6])
    pts, nrm = [], []
    faces = [(0, 0), (0, 1), (1, 0), (1, 1), (2, 0)]
    areas = np.array([np.prod(np.delete(hi - lo, axis)) for axis, _ in faces])
    for (axis, side), share in zip(faces, areas / areas.sum()):
        q = rng.uniform(lo, hi, (int(n * share), 3))
        q[:, axis] = hi[axis] if side else lo[axis]
        inward = np.zeros(3)
        inward[axis] = -1.0 if side else 1.0
        pts.append(q)
        nrm.append(np.tile(inward, (len(q), 1)))
    return np.concatenate(pts), np.concatenate(nrm)


def sphere_in_fragments(n=30000, centre=(4.0, -2.0, 1.5)):
    """A sphere with a hole at the top, cut by gaps into seven patches (six bands above the
    equator's gap, one below): a multi-view scan's pieces, each an open sheet."""
    p, out = fibonacci_sphere(n, 1.0, centre)
    lon = np.degrees(np.arctan2(out[:, 1], out[:, 0])) % 60
    keep = (out[:, 2] < 0.85) & (lon > 8) & (np.abs(out[:, 2]) > 0.12)
    return p[keep], out[keep]


def test_a_sphere_written_as_las_faces_outward(tmp_path):
    """The LAS rule ("normals face up") turned such an object inside-out (51 % right)."""
    p, out = fibonacci_sphere(20000, 3.0, (5.0, 3.0, 1.0))
    prepared, pos, nrm = _load(_write_las(tmp_path / "sphere.las", p))
    assert prepared.normals_oriented == "VISIBILITY"
    assert _right(nrm, (pos - [5.0, 3.0, 1.0]) / 3.0) == 1.0
    note = next(s for s in prepared.notes(16) if "oriented" in s)
    assert "decided by visibility" in note and "escaping" in note, note


@pytest.mark.parametrize("suffix", ["las", "ply"])
def test_a_terrain_faces_up_whatever_its_format(tmp_path, suffix):
    p, up = terrain(60000)
    write = _write_las if suffix == "las" else _write_ply
    prepared, pos, nrm = _load(write(tmp_path / f"terrain.{suffix}", p))
    assert prepared.normals_oriented == "UP"
    assert _right(nrm, up) == 1.0
    note = next(s for s in prepared.notes(16) if "oriented" in s)
    assert "decided by terrain" in note and "by that rule" in note, note


@pytest.mark.parametrize("forward", [-1.0, 1.0])
def test_a_depth_frame_faces_its_sensor_at_the_origin(tmp_path, forward):
    """No viewpoint in the file: the range image seen from the origin is recognised. Looking
    along +Z (PCL's frames), the open-sheet rule turned every normal away (0 %)."""
    p, truth = box_room_frame(forward=forward)
    prepared, pos, nrm = _load(_write_xyz(tmp_path / "frame.xyz", p))
    assert prepared.normals_oriented == "ORIGIN"
    facing = float((np.einsum("ij,ij->i", nrm, -pos) > 0).mean())
    assert facing >= 0.95, facing
    assert _right(nrm, truth) >= 0.95
    note = next(s for s in prepared.notes(16) if "oriented" in s)
    assert "range image seen from the file's origin" in note, note


def test_a_closed_object_with_a_hole_in_fragments_faces_outward_by_visibility(tmp_path):
    """Each fragment is an open sheet: the open-sheet rule turned them all up (45 % right)."""
    p, out = sphere_in_fragments()
    prepared, pos, nrm = _load(_write_ply(tmp_path / "fragments.ply", p))
    assert prepared.normals_oriented == "VISIBILITY"
    assert _right(nrm, out) == 1.0


def test_a_room_seen_from_inside_faces_inward_from_the_file_origin(tmp_path):
    """Rays from the floor escape downward through nothing: visibility alone turns the room
    inside-out. Its lines of sight from the origin spread over more than a half space, as an
    object's around its own origin do (below), so AUTO does not take it for one view; the
    File Origin mode orients it."""
    p, inward = open_box()
    path = _write_xyz(tmp_path / "room.xyz", p)
    prepared, pos, nrm = _load(path)
    assert prepared.normals_oriented != "ORIGIN"
    prepared = importer.load(path, importer.ImportOptions(orientation="ORIGIN"))
    assert prepared.normals_oriented == "ORIGIN"
    assert _right(prepared.cloud.normals.astype(np.float64), inward) == 1.0


@pytest.mark.parametrize("bottom", (-0.5, 0.0))
def test_an_object_around_its_origin_without_its_bottom_faces_outward(tmp_path, bottom):
    """A scanned object exported centred on its origin, its underside never seen: one layer
    per direction from the origin, but no camera's view (the lines of sight spread over a
    half space or more). Taken for a depth frame, it faced inwards on every point."""
    p, out = fibonacci_sphere(20000, 1.0)
    keep = p[:, 2] > bottom
    prepared, pos, nrm = _load(_write_xyz(tmp_path / "cap.xyz", p[keep]))
    assert prepared.normals_oriented != "ORIGIN"
    assert _right(nrm, out[keep]) == 1.0


def test_a_closed_object_around_its_own_origin_faces_outward(tmp_path):
    """One layer per direction from the origin too, but every direction covered: an object
    centred on its origin (the usual export), not a room."""
    p, out = fibonacci_sphere(20000, 1.0)
    prepared, pos, nrm = _load(_write_xyz(tmp_path / "ball.xyz", p))
    assert prepared.normals_oriented != "ORIGIN"
    assert _right(nrm, out) == 1.0


def test_range_image_test_on_a_closed_object_seen_from_outside():
    """Its back is a second layer along every line of sight: no range image."""
    p, out = fibonacci_sphere(20000, 1.0, (0.0, 0.0, -5.0))
    table = np.empty((len(p), normals.GRAPH_K + 1), np.int32)
    axes = normals.estimate(p, graph=table)
    seen, evidence = normals.range_image(p, axes, np.zeros(3), table)
    assert not seen and evidence == ""


def test_visibility_abstains_on_an_open_sheet():
    """A terrain's points see out on both sides: no clear vote, so the terrain rule decides."""
    p, up = terrain(20000)
    axes = normals.estimate(p)
    result = normals.orient(p, axes, "AUTO")
    assert result.mode == "UP" and "terrain" in result.evidence
    assert _right(result.normals.astype(float), up) == 1.0


def _sphere_and_ground(ground_low):
    """A closed sphere (20k points, radius 2 about (0, 0, 4)) and a flat ground of 60k points,
    20 x 20 from `ground_low` (x, y) at z = 0: a terrain's share of the points."""
    s, out = fibonacci_sphere(20000, 2.0, (0.0, 0.0, 4.0))
    rng = np.random.default_rng(0)
    lo = np.asarray(ground_low, float)
    g = np.column_stack([rng.uniform(lo, lo + 20.0, (60000, 2)), np.zeros(60000)])
    p = np.concatenate([s, g])
    result = normals.orient(p, normals.estimate(p), "AUTO")
    nrm = result.normals.astype(np.float64)
    return result, _right(nrm[:20000], out), float((nrm[20000:, 2] > 0).mean())


def test_a_terrain_leaves_the_components_visibility_decided():
    """The terrain's upward rule on every point overrode the sphere beside the ground, which
    visibility had decided: its lower half faced inward (49.7 % right)."""
    result, sphere, ground = _sphere_and_ground((5.0, -10.0))
    assert result.mode == "UP" and "terrain" in result.evidence and "visibility: 1 of 2" in result.evidence
    assert sphere >= 0.99 and ground == 1.0, (sphere, ground)


def test_visibility_probes_spread_over_their_component():
    """The probes were a component's first sample points in the spatial renumbering, all on
    the sphere's underside, whose outward rays meet the ground beneath: visibility abstained,
    and the terrain rule turned the sphere's lower half inward (49.7 % right)."""
    result, sphere, ground = _sphere_and_ground((-10.0, -10.0))
    assert "visibility: 1 of 2" in result.evidence, result.evidence
    assert sphere >= 0.99 and ground == 1.0, (sphere, ground)


@pytest.mark.filterwarnings("error")
def test_visibility_abstains_without_a_word_on_duplicate_points():
    """Points each repeated more often than the graph has neighbours (mesh vertices not merged)
    have no discs: visibility had no probes, and its note read '0 probes ... nan% / nan%'
    with RuntimeWarnings. The graph's propagation decides alone (each group of duplicates
    is a component of its own: it faces up)."""
    p, out = fibonacci_sphere(500, 1.0)
    p, out = np.repeat(p, normals.GRAPH_K + 2, axis=0), np.repeat(out, normals.GRAPH_K + 2, axis=0)
    result = normals.orient(p, out, "AUTO")
    assert result.mode == "PROPAGATE" and result.evidence == "", (result.mode, result.evidence)
    groups = result.normals.reshape(500, normals.GRAPH_K + 2, 3)
    assert (groups == groups[:, :1]).all() and (groups[:, 0, 2] >= 0).all()


def test_the_notes_say_what_decided_and_what_was_tried(tmp_path):
    """An abstention was presented as the decider ('decided by visibility abstained'), and
    'the rest from their neighbours' was said when no point was left."""
    rng = np.random.default_rng(0)
    wall = np.column_stack([np.zeros(5000), rng.uniform(-2, 2, (5000, 2))])  # seen edge-on from its origin
    prepared = importer.load(_write_xyz(tmp_path / "wall.xyz", wall))
    note = next(s for s in prepared.notes(16) if "oriented" in s)
    assert prepared.normals_oriented == "PROPAGATE"
    assert "neighbour graph (outward where the surface encloses a volume), after visibility abstained: " in note, note
    assert "decided by" not in note, note
    ground = np.column_stack([rng.uniform(-2, 2, (5000, 2)), np.zeros(5000)])
    prepared = importer.load(_write_xyz(tmp_path / "ground.xyz", ground), importer.ImportOptions(orientation="UP"))
    note = next(s for s in prepared.notes(16) if "oriented" in s)
    assert note.endswith("oriented upward (+Z); 100.0% of the points by that rule"), note
