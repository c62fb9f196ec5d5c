"""Property-based tests of the native core (issue #9): invariants that must hold for every
input hypothesis draws, not only for the hand-picked cases of the other test files.

Deterministic: every test runs under the "splat" profile below (derandomize=True, no
example database), so the same examples run on every machine and in CI; the example
counts are fixed per test (EXAMPLES). In all, 1,740 examples (about 20 s on 2 cores; well
under a minute in `make test-sanitize`):

- translation (100): a closed sphere cloud moved anywhere within 1e7 of the origin and
  recentred with local_frame renders the same passes as at the origin: coverage to 4
  pixels of 3072, planar depth to 1e-5 relative, normals to 0.06 degrees (99 % of pixels;
  the rest are rim pixels where the surface hit may change splat).
- scale (100): the cloud and the camera scaled by 1e-4 .. 1e4: same coverage (to 4 pixels),
  depth / scale to 1e-5 relative, normals to 0.06 degrees.
- rotation (100): the cloud and the camera rotated: same coverage (to 1 %), depth to 1e-4
  relative and rotated normals to 0.5 degrees on 98 % of the pixels (a rotation changes
  every float32 rounding, so rays near a silhouette or a splat's rim may see a neighbour).
- rotation of a RenderScene instance (50): the same sphere placed by an instance matrix
  (rotation, scale, translation) and seen by the transformed camera gives the same Depth
  and Normal passes; every Combined value is finite.
- no holes (200): a plane of overlapping discs -- randomly jittered, with every disc
  duplicated (coplanar duplicates), or on a square grid with radius h / sqrt(2) so that
  four rims meet at every cell centre (shared rims) -- rotated anywhere, scaled by
  1e-3 .. 1e3 and hit by a grid of parallel rays tilted up to 85 degrees from the normal
  (grazing) and aimed at the cell centres where rims meet: every ray into the interior
  hits, for trace, trace_surface (FULL and GENERAL) and render.
- camera direction (40): the traversal cost (BVH nodes entered, never timings) of views
  along each of the 6 axis directions and the 8 diagonals of a rotated or axis-aligned
  sphere and of an axis-aligned cube differs by less than 2x between the cheapest and the
  dearest view, for orthographic and perspective cameras alike.
- secondary rays (150): from every surface point of a closed sphere cloud at scale
  1e-4 .. 1e4, a ray leaving along the shading normal tilted up to 70 degrees, with
  exclude = the hit's members, hits nothing (a convex object cannot see itself).
- degenerate inputs (1,000, in a subprocess so that a crash fails the test instead of
  killing the session): scenes and rays built from NaN, inf, 0, -0, denormals, 1e19,
  float32-extreme values, empty, single and identical rows are refused with ValueError or
  TypeError, or accepted; accepted scenes trace, trace_surface and render without crashing
  and return finite results or misses.
"""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from geometry import angle_deg, cube_cloud, fibonacci_sphere
from splat_tracer.pointcloud.neighbours import local_frame
from splat_tracer.render.camera import Camera
from splat_tracer.render.method import KERNELS, POSITION_RULES, Method
from splat_tracer.render.scene import Instance, RenderScene
from splat_tracer.render.shading import Light, RenderSettings
from splat_tracer.render.splats import SplatCloud

ROOT = Path(__file__).resolve().parents[2]

settings.register_profile("splat", derandomize=True, database=None, deadline=None, print_blob=True,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
settings.load_profile("splat")

EXAMPLES = dict(translation=100, scale=100, rotation=100, instance=50, holes=200, camera=40, secondary=150,
                degenerate=1000)

FULL = Method.preset("FULL")
GENERAL = Method.preset("GENERAL")
W, H = 64, 48

# ---------------------------------------------------------------------------------------
# Shapes and strategies


def sphere(n: int = 6000):
    """A closed unit sphere: centres, normals, radii (1.5x the mean spacing)."""
    p, nrm = fibonacci_sphere(n)
    return p, nrm, np.full(n, 1.5 * np.sqrt(4 * np.pi / n))


SPHERE = sphere()
EYE, TARGET, UP = np.array([0.4, -3.5, 1.1]), np.array([0.02, 0.01, -0.03]), np.array([0.0, 0.0, 1.0])


def rotation(q) -> np.ndarray:
    """The rotation matrix of a (not necessarily unit, non-zero) quaternion."""
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


quaternions = st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda q: np.linalg.norm(q) > 0.1)
log_scales = st.floats(-4, 4).map(lambda e: 10.0 ** e)


def render(scene, eye, target, up=UP, scale=1.0):
    cam = Camera.look_at(eye, target, up, fov_y=40, aspect=W / H, near=1e-3 * scale, far=1e3 * scale)
    return scene.render(cam, W, H, method=FULL, threads=2)


def compare_passes(a, b, depth_scale=1.0, rotate=np.eye(3), coverage_px=4, depth_rel=1e-5, normal_deg=0.06,
                   share=0.99):
    """b is a's scene moved by a similarity: same coverage, depth x depth_scale, rotated normals."""
    hit_a, hit_b = a.rgba[..., 3] > 0, b.rgba[..., 3] > 0
    assert hit_a.sum() > 0.2 * hit_a.size
    assert (hit_a != hit_b).sum() <= coverage_px, (hit_a != hit_b).sum()
    both = hit_a & hit_b
    rel = np.abs(b.depth[both] / depth_scale - a.depth[both]) / a.depth[both]
    err = angle_deg(b.normal[both], a.normal[both] @ rotate.T)
    assert np.mean(rel <= depth_rel) >= share, np.quantile(rel, [0.5, 0.99, 1])
    assert np.mean(err <= normal_deg) >= share, np.quantile(err, [0.5, 0.99, 1])
    assert rel.max() < 0.05 and err.max() < 30  # what differs is a neighbouring splat, never garbage


@pytest.fixture(scope="module")
def reference():
    c, n, r = SPHERE
    scene = SplatCloud(c, n, r, closed=True)
    return render(scene, EYE, TARGET)


# ---------------------------------------------------------------------------------------
# Invariance


@settings(max_examples=EXAMPLES["translation"])
@given(offset=st.lists(st.floats(-1e7, 1e7), min_size=3, max_size=3))
def test_translation_with_recentring_changes_nothing(reference, offset):
    c, n, r = SPHERE
    offset = np.asarray(offset)
    origin, local = local_frame(c + offset)  # what the importer stores
    scene = SplatCloud(local, n, r, closed=True)
    shift = offset - origin  # where the cloud's own origin lies in the local frame (float64)
    compare_passes(reference, render(scene, EYE + shift, TARGET + shift))


@settings(max_examples=EXAMPLES["scale"])
@given(scale=log_scales)
def test_scale_changes_nothing_but_depth(reference, scale):
    c, n, r = SPHERE
    scene = SplatCloud(c * scale, n, r * scale, closed=True)
    compare_passes(reference, render(scene, EYE * scale, TARGET * scale, scale=scale), depth_scale=scale)


@settings(max_examples=EXAMPLES["rotation"])
@given(q=quaternions)
def test_rotation_rotates_the_normals_and_nothing_else(reference, q):
    c, n, r = SPHERE
    rot = rotation(q)
    scene = SplatCloud(c @ rot.T, n @ rot.T, r, closed=True)
    b = render(scene, rot @ EYE, rot @ TARGET, rot @ UP)
    compare_passes(reference, b, rotate=rot, coverage_px=0.01 * W * H, depth_rel=1e-4, normal_deg=0.5, share=0.98)


@pytest.fixture(scope="module")
def instance_reference():
    c, n, r = SPHERE
    geometry = SplatCloud(c, n, r, closed=True)
    return geometry, render_instance(geometry, np.eye(4), EYE, TARGET, UP)


def render_instance(geometry, matrix, eye, target, up):
    scene = RenderScene([Instance(geometry, matrix=tuple(map(tuple, matrix)))],
                        [Light("POINT", power=500.0, position=tuple(eye))])
    cam = Camera.look_at(eye, target, up, fov_y=40, aspect=W / H, near=1e-3, far=1e4)
    settings_ = RenderSettings(samples=1, pixel_filter="BOX", filter_width=1.0, diffuse_bounces=0,
                               glossy_bounces=0)
    return scene.render(cam, W, H, settings_, FULL, passes=("Depth", "Normal"), threads=2)


@settings(max_examples=EXAMPLES["instance"])
@given(q=quaternions, scale=st.floats(-1, 1).map(lambda e: 10.0 ** e),
       move=st.lists(st.floats(-100, 100), min_size=3, max_size=3))
def test_render_scene_instance_transform_changes_nothing(instance_reference, q, scale, move):
    """The same sphere placed by an instance matrix (similarity), seen by the camera moved
    with it: the object-space queries give the same passes."""
    geometry, ref = instance_reference
    rot = rotation(q)
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot * scale, move
    world = lambda p: rot @ (np.asarray(p) * scale) + move
    got = render_instance(geometry, m, world(EYE), world(TARGET), rot @ UP)
    assert all(np.isfinite(p).all() for p in got.passes.values())
    hit_a, hit_b = ref.passes["Depth"] < 1e9, got.passes["Depth"] < 1e9
    assert hit_a.sum() > 0.2 * hit_a.size and (hit_a != hit_b).mean() < 0.01
    both = hit_a & hit_b
    rel = np.abs(got.passes["Depth"][both] / scale - ref.passes["Depth"][both]) / ref.passes["Depth"][both]
    err = angle_deg(got.passes["Normal"][both], ref.passes["Normal"][both] @ rot.T)
    assert np.mean(rel < 1e-4) > 0.98 and np.mean(err < 0.5) > 0.98, (np.quantile(rel, 0.99), np.quantile(err, 0.99))


# ---------------------------------------------------------------------------------------
# No holes: grazing rays, rims, shared rims, coplanar duplicates


def plane_of_discs(kind: str, rng, m: int = 24):
    """Discs covering the square [-m/2, m/2]^2 of the z = 0 plane (spacing 1), and the
    in-plane points the rays aim at. 'jitter': randomly moved centres, radius 1.2;
    'duplicates': a jittered grid whose every disc appears twice (the second with the
    opposite normal half of the time, a scanner's double-sided sheet); 'shared_rims': a
    square grid with radius sqrt(1/2) (1 + 1e-4), so four rims meet at every cell centre
    (to 1e-4 of the radius: exactly meeting rims would not meet once rounded to float32),
    which the rays aim at."""
    g = np.arange(m) - (m - 1) / 2
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    centres = np.column_stack([x, y, np.zeros_like(x)])
    normals = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    if kind == "shared_rims":  # rims meeting to within 1e-4 of the radius (exactly, float32 rounds apart)
        radii = np.full(len(x), np.sqrt(0.5) * (1 + 1e-4))
        h = g[:-1] + 0.5  # cell centres
        tx, ty = (a.ravel() for a in np.meshgrid(h, h))
    else:
        centres[:, :2] += rng.uniform(-0.2, 0.2, (len(x), 2))
        radii = np.full(len(x), 1.2)
        tx, ty = (a.ravel() for a in np.meshgrid(*[np.linspace(-m / 2 + 3, m / 2 - 3, 23)] * 2))
        tx, ty = tx + rng.uniform(-0.5, 0.5, tx.shape), ty + rng.uniform(-0.5, 0.5, ty.shape)
    if kind == "duplicates":
        flip = np.where(rng.uniform(size=len(x)) < 0.5, -1.0, 1.0)[:, None]
        centres, normals, radii = (np.concatenate([centres, centres]), np.concatenate([normals, normals * flip]),
                                   np.concatenate([radii, radii]))
    inner = (np.abs(tx) < m / 2 - 3) & (np.abs(ty) < m / 2 - 3)
    return centres, normals, radii, np.column_stack([tx, ty, np.zeros_like(tx)])[inner]


@settings(max_examples=EXAMPLES["holes"])
@given(kind=st.sampled_from(["jitter", "duplicates", "shared_rims"]), q=quaternions, scale=st.floats(-3, 3),
       tilt=st.floats(0, 85), azimuth=st.floats(0, 360), seed=st.integers(0, 2**16))
def test_plane_of_overlapping_discs_has_no_holes(kind, q, scale, tilt, azimuth, seed):
    rng = np.random.default_rng(seed)
    centres, normals, radii, targets = plane_of_discs(kind, rng)
    s, rot = 10.0 ** scale, rotation(q)
    a, t = np.radians(tilt), np.radians(azimuth)
    d_plane = np.array([np.sin(a) * np.cos(t), np.sin(a) * np.sin(t), -np.cos(a)])  # towards the front side
    scene = SplatCloud(centres @ rot.T * s, normals @ rot.T, radii * s, closed=False)
    points = targets @ rot.T * s
    d = np.tile(rot @ d_plane, (len(points), 1))
    o = points - d * (5.0 * s)
    for name, res in (("trace", scene.trace(o, d)), ("FULL", scene.trace_surface(o, d, FULL)),
                      ("GENERAL", scene.trace_surface(o, d, GENERAL))):
        holes = np.flatnonzero(res.id < 0)
        assert len(holes) == 0, f"{name}: {len(holes)} of {len(d)} rays miss, e.g. aimed at {targets[holes[:3]]}"
    # render(): an orthographic view straight down the tilted direction, inside the plane's interior.
    eye = -d_plane * 20.0  # far enough that the whole near plane is above the discs
    up = np.cross(d_plane, [1.0, 0.0, 0.0] if abs(d_plane[0]) < 0.9 else [0.0, 1.0, 0.0])
    height = 10.0 * np.cos(a)  # the view's footprint stays inside the interior
    cam = Camera.look_at(rot @ eye * s, np.zeros(3), rot @ up, ortho_height=height * s, aspect=1.0,
                         near=1e-3 * s, far=50 * s)
    img = scene.render(cam, 24, 24, method=FULL, threads=2)
    assert (img.rgba[..., 3] == 1).all(), f"render: {(img.rgba[..., 3] < 1).sum()} empty pixels"


# ---------------------------------------------------------------------------------------
# Cost of view directions (traversal work, never timings)

DIRECTIONS = [v / np.linalg.norm(v) for v in
              [*np.eye(3), *-np.eye(3), *[np.array([x, y, z]) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]]]


def cube_surface(per_edge: int = 40):
    """The tests' cube cloud (geometry.cube_cloud) with radii of 1.5 grid steps."""
    pts, nrm = cube_cloud(per_edge)
    return pts, nrm, np.full(len(pts), 1.5 * 2 / per_edge)


CUBE = cube_surface()


@settings(max_examples=EXAMPLES["camera"])
@given(shape=st.sampled_from(["sphere", "rotated sphere", "cube"]), ortho=st.booleans(),
       distance=st.floats(2.5, 10))
def test_view_direction_does_not_change_the_cost(shape, ortho, distance):
    c, n, r = CUBE if shape == "cube" else SPHERE
    if shape == "rotated sphere":
        rot = rotation([0.3, -0.5, 0.7, 0.2])
        c, n = c @ rot.T, n @ rot.T
    scene = SplatCloud(c, n, r, closed=True)
    costs = []
    for d in DIRECTIONS:
        up = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
        fov = 2 * np.degrees(np.arctan(1.9 / distance))  # the object fills the same share of the view
        cam = Camera.look_at(d * distance, np.zeros(3), up, fov_y=fov, aspect=1.0,
                             ortho_height=3.8 if ortho else None)
        costs.append(scene.traversal_cost(*cam.rays(40, 40))["nodes"])
    assert max(costs) < 2.0 * min(costs), dict(zip(map(tuple, np.round(DIRECTIONS, 2)), costs))


# ---------------------------------------------------------------------------------------
# Secondary rays


@settings(max_examples=EXAMPLES["secondary"])
@given(scale=log_scales, q=quaternions, tilt=st.floats(0, 70), azimuth=st.floats(0, 360),
       offset=st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3))
def test_secondary_rays_leaving_a_convex_cloud_hit_nothing(scale, q, tilt, azimuth, offset):
    c, n, r = SPHERE
    rot = rotation(q)
    offset = np.asarray(offset) * scale
    scene = SplatCloud(c @ rot.T * scale + offset, n @ rot.T, r * scale, closed=True)
    cam = Camera.look_at((EYE * 1.0) * scale + offset, offset, fov_y=40, aspect=1.0, near=1e-3 * scale,
                         far=1e3 * scale)
    o, d = cam.rays(40, 40)
    prim = scene.trace_surface(o, d, FULL, members=True)
    ok = prim.id >= 0
    assert ok.sum() > 300
    start = o[ok].astype(np.float64) + d[ok] * prim.t[ok, None]
    nrm = prim.normal[ok].astype(np.float64)
    # The normal tilted by `tilt` towards a tangent direction of the given azimuth.
    helper = np.where(np.abs(nrm[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(nrm, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(nrm, u)
    a, b = np.radians(tilt), np.radians(azimuth)
    out = nrm * np.cos(a) + (u * np.cos(b) + v * np.sin(b)) * np.sin(a)
    res = scene.trace_surface(start, out, FULL, exclude=prim.members[ok])
    hits = np.flatnonzero(res.id >= 0)
    assert len(hits) == 0, f"{len(hits)} of {len(out)} secondary rays hit the cloud they leave (t = {res.t[hits[:3]]})"


# ---------------------------------------------------------------------------------------
# Degenerate inputs: refused or handled, never a crash

SPECIAL = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1e-45, -1e-45, 1.2e-38, 1e19, -1e19, 1e18, -1e18,
           3.4028235e38, -3.4028235e38, 1.0, -1.0, 0.5, 1e-20, 65504.0]
values = st.one_of(st.sampled_from(SPECIAL), st.floats(width=32, allow_nan=True, allow_infinity=True))


@st.composite
def float_rows(draw, max_rows=6, columns=3):
    """Rows of special floats: empty, single, identical (one row repeated) or arbitrary."""
    n = draw(st.integers(0, max_rows))
    if draw(st.booleans()):  # identical rows
        row = draw(st.lists(values, min_size=columns, max_size=columns))
        return np.array([row] * n, np.float32).reshape(n, columns)
    return np.array(draw(st.lists(st.lists(values, min_size=columns, max_size=columns), min_size=n, max_size=n)),
                    np.float32).reshape(n, columns)


def _exercise(scene, rays, method_args, window):
    """Every query of an accepted scene: refusals are fine, anything else must be sane."""
    o, d = rays
    for call in (lambda: scene.trace(o, d), lambda: scene.trace_surface(o, d, Method(*method_args), members=True),
                 lambda: scene.trace_surface(o, d, FULL, exclude=np.full((len(o), 2), len(scene) - 1, np.int32),
                                             inside=True)):
        try:
            res = call()
        except (ValueError, TypeError):
            continue
        hit = res.id >= 0
        assert np.all((res.id >= -1) & (res.id < max(len(scene), 1)))
        assert np.all(np.isinf(res.t[~hit])) and np.all(np.isfinite(res.t[hit]))
        assert np.isfinite(res.normal).all()
    cam = Camera.look_at((0, -3, 0.5), (0, 0, 0), fov_y=40, aspect=4 / 3)
    try:
        img = scene.render(cam, 8, 6, window=window, method=Method(*method_args), threads=2)
    except (ValueError, TypeError):
        return
    assert np.isfinite(img.rgba).all() and np.isfinite(img.depth).all()


methods = st.tuples(st.booleans(), st.booleans(), st.booleans(), st.sampled_from(POSITION_RULES),
                    st.sampled_from(KERNELS), st.sampled_from([0.0, 1e-30, 1.0, 1e30, 3.4e38]))


@settings(max_examples=EXAMPLES["degenerate"])
@given(centres=float_rows(), normals=float_rows(), radii=float_rows(columns=1), closed=st.booleans(),
       origins=float_rows(max_rows=3), directions=float_rows(max_rows=3), method=methods,
       window=st.one_of(st.none(), st.tuples(*[st.sampled_from([-1, 0, 1, 7, 8, 2**31 - 1])] * 4)))
def degenerate_inputs_body(centres, normals, radii, closed, origins, directions, method, window):
    """Runs in a subprocess (see the test below)."""
    n = min(len(centres), len(normals), len(radii))
    k = min(len(origins), len(directions))
    with open(os.environ["SPLAT_LAST_EXAMPLE"], "w") as f:  # what was running if the process dies
        f.write(repr((centres[:n], normals[:n], radii[:n, 0], closed, origins[:k], directions[:k], method, window)))
    try:
        scene = SplatCloud(centres[:n], normals[:n], radii[:n, 0], closed=closed, threads=2)
    except (ValueError, TypeError):
        scene = None
    if scene is not None:
        assert len(scene) == n
        _exercise(scene, (origins[:k], directions[:k]), method, window)
    # Mismatched shapes are refused, never read out of bounds.
    if len(centres) != len(normals):
        with pytest.raises((ValueError, TypeError)):
            SplatCloud(centres, normals, radii[:len(centres), 0])


def test_degenerate_inputs_are_refused_or_handled_never_crash(tmp_path):
    last = tmp_path / "last_example.txt"
    code = textwrap.dedent("""
        from tests.render import test_invariants
        test_invariants.degenerate_inputs_body()
    """)
    # From the root, with support/ importable: the imports pytest.ini's pythonpath gives the tests.
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, cwd=ROOT,
                            env={**os.environ, "SPLAT_LAST_EXAMPLE": str(last),
                                 "PYTHONPATH": str(ROOT / "tests" / "support")})
    example = last.read_text() if last.exists() else "?"
    assert result.returncode == 0, f"exit {result.returncode}\n{result.stderr[-4000:]}\nlast example: {example}"
