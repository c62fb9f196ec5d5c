"""The paper's visibility method in the core: each rule, and what breaks when it is off."""
from __future__ import annotations

from dataclasses import asdict, fields, replace
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from geometry import angle_deg, cube_cloud, fibonacci_sphere, ray_box, ray_sphere
from splat_tracer.pointcloud import spacing
from splat_tracer.render.camera import Camera
from splat_tracer.render import ab
from splat_tracer.render.method import POSITION_RULES, PRESETS, SWITCHES, Method, switch_fields, switches_of
from splat_tracer.render.splats import SplatCloud

W, H = 320, 240
FULL = Method.preset("FULL")


def cloud_scene(points, normals, closed, radius_factor=1.0):
    radii, _ = spacing.knn_spacing(points)
    return SplatCloud(points, normals, radii * radius_factor, closed=closed), radii


def camera_rays(eye, target=(0, 0, 0), fov_y=35.0):
    cam = Camera.look_at(eye, target, fov_y=fov_y, aspect=W / H)
    return cam.rays(W, H)


def pixels_from_edge(mask: np.ndarray) -> np.ndarray:
    """Per pixel, the distance in pixels to the nearest pixel of the other coverage."""
    return np.maximum(distance_transform_edt(mask), distance_transform_edt(~mask))


def test_ε_window_query_matches_brute_force():
    """The one-traversal query with its shrinking interval gives exactly what offering every
    splat to the same query gives, for every method and both ray roles."""
    rng = np.random.default_rng(21)
    p, n = fibonacci_sphere(3000)
    centres = np.concatenate([p, p * 0.6 + 0.05])  # two nested closed shells
    normals = np.concatenate([n, n])
    scene = SplatCloud(centres, normals, np.full(len(centres), 0.07), closed=True)
    origins = rng.uniform(-2, 2, size=(6000, 3))
    dirs = rng.normal(size=(6000, 3))
    inside = rng.uniform(size=6000) < 0.3
    for method in (FULL, Method.preset("NEAREST_CENTRE"), Method.preset("GENERAL"),
                   Method.preset("FULL", wrong_hit_elimination=False, epsilon=2.5)):
        a = scene.trace_surface(origins, dirs, method, inside=inside, members=True)
        b = scene.trace_surface(origins, dirs, method, inside=inside, members=True, brute_force=True)
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)
        assert 0.05 < (a.id >= 0).mean() < 0.95


def test_ε_window_query_does_not_depend_on_the_order_hits_arrive():
    """With radii that vary from splat to splat, a nearer first hit met late in the
    traversal can have a larger window than the first hit met before it: the query must not
    have dropped the hits in between (it did, on 1 to 3 of the bunny's 76,800 rays). BVH and
    brute force -- two different orders -- agree exactly on every ray."""
    rng = np.random.default_rng(8)
    p, n = fibonacci_sphere(6000)
    p = p + rng.normal(scale=0.01, size=p.shape)  # a rough surface: layers of several depths
    radii = 0.03 * rng.uniform(0.5, 3.0, size=len(p))  # 6x from the smallest to the largest
    scene = SplatCloud(p, n, radii, closed=True)
    origins = rng.uniform(-2, 2, size=(20000, 3))
    dirs = -origins + rng.normal(scale=0.3, size=origins.shape)  # towards the sphere, mostly
    for method in (FULL, Method.preset("NEAREST_CENTRE"), Method.preset("FULL", epsilon=3.0)):
        a = scene.trace_surface(origins, dirs, method, members=True)
        b = scene.trace_surface(origins, dirs, method, members=True, brute_force=True)
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)


def test_sphere_interpolated_normals_are_smooth_and_flat_ones_are_not():
    """Interpolated normals stay within 2 degrees of the analytic normal at every pixel
    (mean below 0.25); flat splat normals are at least 4 times worse on average."""
    p, n = fibonacci_sphere(20000)
    scene, _ = cloud_scene(p, n, closed=True)
    o, d = camera_rays((0.5, -4.0, 1.2))
    t_true = ray_sphere(o.astype(np.float64), d.astype(np.float64), np.zeros(3), 1.0)
    hit = np.isfinite(t_true)
    truth = o + d * np.where(hit, t_true, 0)[:, None]
    smooth = scene.trace_surface(o, d, FULL)
    flat = scene.trace_surface(o, d, Method.preset("FULL", normal_interpolation=False))
    both = hit & (smooth.id >= 0)
    assert both.sum() > 0.99 * hit.sum()
    err_smooth = angle_deg(smooth.normal[both], truth[both])
    err_flat = angle_deg(flat.normal[both], truth[both])
    assert err_smooth.max() < 2.0 and err_smooth.mean() < 0.25, (err_smooth.max(), err_smooth.mean())
    assert err_flat.mean() > 4 * err_smooth.mean()
    smooth_kernel = scene.trace_surface(o, d, Method.preset("FULL", kernel="SMOOTH"))
    assert angle_deg(smooth_kernel.normal[both], truth[both]).max() < 2.0


@pytest.fixture(scope="module")
def cube():
    p, n = cube_cloud(60)
    scene, radii = cloud_scene(p, n, closed=True)
    o, d = camera_rays((2.5, -4.0, 3.0))
    t_true, n_true = ray_box(o.astype(np.float64), d.astype(np.float64))
    return scene, o, d, np.isfinite(t_true).reshape(H, W), t_true, n_true


def test_cube_far_phase_gives_the_true_silhouette(cube):
    """With the far phase the coverage matches the analytic cube to about a pixel; without
    it, the discs sticking out of the edges show as a fringe several pixels wide."""
    scene, o, d, truth, t_true, _ = cube
    edge = pixels_from_edge(truth)
    full = (scene.trace_surface(o, d, FULL).id >= 0).reshape(H, W)
    wrong = full != truth
    assert wrong.sum() < 20 and edge[wrong].max() <= 1.5, (wrong.sum(), edge[wrong].max())
    no_far = (scene.trace_surface(o, d, Method.preset("FULL", far_phase=False)).id >= 0).reshape(H, W)
    fringe = no_far & ~truth
    assert fringe.sum() > 200 and edge[fringe].max() >= 2.0
    general = (scene.trace_surface(o, d, Method.preset("GENERAL")).id >= 0).reshape(H, W)
    assert (general & ~truth).sum() > 200


def test_cube_full_method_puts_the_surface_on_the_cube(cube):
    """Depth: the full method's surface points lie on the cube's faces (flat normals are
    then exactly the face normals); the general method's fringe and edge hits do not."""
    scene, o, d, truth, t_true, n_true = cube
    flat_full = scene.trace_surface(o, d, Method.preset("FULL", normal_interpolation=False))
    both = (flat_full.id >= 0) & np.isfinite(t_true)
    np.testing.assert_allclose(flat_full.t[both], t_true[both], atol=1e-4)
    np.testing.assert_array_equal(flat_full.normal[both], n_true[both])
    general = scene.trace_surface(o, d, Method.preset("GENERAL"))
    both = (general.id >= 0) & np.isfinite(t_true)
    assert np.abs(general.t[both] - t_true[both]).max() > 0.02


def test_crease_angle_keeps_cube_edges_sharp_and_spheres_smooth(cube):
    """Interpolation blends the discs of both faces over about a radius at each edge (up to
    45 degrees off the face there); with a crease angle, only the surface splat's side blends
    and every pixel has its face's normal. On a smooth sphere the crease angle changes
    nothing: neighbouring normals differ by a few degrees."""
    scene, o, d, _, t_true, n_true = cube
    blended = scene.trace_surface(o, d, FULL)
    sharp = scene.trace_surface(o, d, Method.preset("FULL", crease_angle=45))
    both = (sharp.id >= 0) & np.isfinite(t_true)
    assert angle_deg(blended.normal[both], n_true[both]).max() > 20
    assert angle_deg(sharp.normal[both], n_true[both]).max() < 0.01
    p, n = fibonacci_sphere(20000)
    sphere, _ = cloud_scene(p, n, closed=True)
    o, d = camera_rays((0.5, -4.0, 1.2))
    a, b = sphere.trace_surface(o, d, FULL), sphere.trace_surface(o, d, Method.preset("FULL", crease_angle=45))
    np.testing.assert_array_equal(a.normal, b.normal)
    with pytest.raises(ValueError, match="crease_angle"):
        Method(crease_angle=200)


# Two discs at a sharp edge (the paper's Figs. 9-10), seen by one ray along -x-z.
# Convex: a roof edge along y at the origin, solid below z = 0 and left of x = 0. Disc A
# lies on the top face with its centre just inside the edge, so its fringe pokes out over
# the side face; disc B lies on the side face. The ray meets A's fringe first, in the air
# (but close to A's centre), then B on the true surface.
RAY_O = np.array([[0.5, 0.0, 0.4]])
RAY_D = np.array([[-1.0, 0.0, -1.0]])
CONVEX = dict(centres=[[-0.02, 0, 0], [0, 0, -0.5]], normals=[[0, 0, 1], [1, 0, 0]], radii=[0.3, 0.8])
# Concave: a floor (z = 0, x > 0) meeting a wall (x = 0, z > 0). The ray meets the floor
# first (the surface) and then, behind it, the wall's fringe below the floor, whose hit is
# the nearer to its own centre.
CONCAVE = dict(centres=[[0.9, 0, 0], [0, 0, 0.02]], normals=[[0, 0, 1], [1, 0, 0]], radii=[1.0, 0.3])


@pytest.mark.parametrize("case, surface, near_centre_pick", [(CONVEX, 1, 0), (CONCAVE, 0, 1)])
def test_near_phase_picks_the_right_hit_at_edges(case, surface, near_centre_pick):
    scene = SplatCloud(case["centres"], case["normals"], case["radii"], closed=False)
    pick = {}
    for position in POSITION_RULES:
        res = scene.trace_surface(RAY_O, RAY_D, Method(position=position, far_phase=False), members=True)
        assert sorted(res.members[0][:2]) == [0, 1]  # both discs are in the layer
        pick[position] = int(res.id[0])
    assert pick["NEAR_PHASE"] == surface
    assert pick["NEAREST_CENTRE"] == near_centre_pick != surface  # Linsen et al. fail here
    assert pick["FIRST"] == 0


def test_near_phase_decides_as_the_papers_omega_on_random_pairs():
    """The core decides omega > pi without acos (visibility.cpp, near_phase_convex): on
    random pairs of discs in one layer, the pick is the paper's rule computed with arccos."""
    rng = np.random.default_rng(8)
    method = Method(position="NEAR_PHASE", far_phase=False, normal_interpolation=False, epsilon=1000.0)
    o, d = np.array([[0.0, 0.0, 5.0]]), np.array([[0.0, 0.0, -1.0]])
    checked = 0
    for _ in range(400):
        c = np.c_[rng.uniform(-0.5, 0.5, (2, 2)), [0.0, rng.uniform(-0.5, 0.5)]]
        n = np.c_[rng.uniform(-1, 1, (2, 2)), rng.uniform(0.3, 1, 2)]
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        t = (np.einsum("ij,ij->i", c - o, n)) / (n @ d[0])  # where the ray meets each disc's plane
        j, k = np.argsort(t)
        cj, nj, ck, nk = c[j], n[j], c[k], n[k]
        dk = ck - cj
        omega = np.arccos(np.dot(dk, nj) / np.linalg.norm(dk)) + np.arccos(np.dot(-dk, nk) / np.linalg.norm(dk))
        if abs(omega - np.pi) < 1e-4:
            continue  # a rounding apart from the threshold either way
        res = SplatCloud(c, n, [10.0, 10.0], closed=False).trace_surface(o, d, method, members=True)
        assert sorted(res.members[0][:2]) == [0, 1]
        assert int(res.id[0]) == (k if omega > np.pi else j), (c, n, omega)
        checked += 1
    assert checked > 390


def test_omega_classifies_convex_and_concave():
    c, n = np.array(CONVEX["centres"]), np.array(CONVEX["normals"])
    # Symmetric roof and valley with faces at 90 degrees: omega = 270 and 90 degrees.
    scene = SplatCloud(c, n, CONVEX["radii"])
    assert scene is not None
    omega = lambda cj, nj, ck, nk: np.degrees(
        np.arccos(np.dot(ck - cj, nj) / np.linalg.norm(ck - cj)) + np.arccos(np.dot(cj - ck, nk) / np.linalg.norm(cj - ck)))
    assert omega(c[0], n[0], c[1], n[1]) > 180
    cc, nn = np.array(CONCAVE["centres"]), np.array(CONCAVE["normals"])
    assert omega(cc[0], nn[0], cc[1], nn[1]) < 180


def slab_cloud(thickness=0.02, step=0.04):
    """A closed 2 x 2 x thickness box sampled on its six faces with face normals."""
    g = np.arange(-1 + step / 2, 1, step)
    u, v = (a.ravel() for a in np.meshgrid(g, g))
    h = thickness / 2
    pts = [np.column_stack([u, v, np.full_like(u, s * h)]) for s in (1, -1)]
    nrm = [np.tile([0, 0, s], (len(u), 1)) for s in (1.0, -1.0)]
    side = g[None, :]
    z = np.zeros(1)
    for axis in (0, 1):
        for s in (1.0, -1.0):
            p = np.zeros((len(g), 3))
            p[:, axis] = s
            p[:, 1 - axis] = g
            pts.append(p)
            nn = np.zeros_like(p)
            nn[:, axis] = s
            nrm.append(nn)
    del side, z
    return np.concatenate(pts), np.concatenate(nrm).astype(float)


@pytest.mark.parametrize("eye, normal", [((0.4, -0.6, 3.0), [0, 0, 1]), ((0.4, -0.6, -3.0), [0, 0, -1])])
def test_thin_closed_slab_renders_from_both_sides(eye, normal):
    """The slab is thinner than a layer (its two sides lie within ε): seen from above or
    below, the first side is the surface, with its own normal, and the far phase accepts
    it because the other side's back-facing hits follow."""
    p, n = slab_cloud()
    radii, _ = spacing.knn_spacing(p)
    assert 0.02 < FULL.epsilon * radii.min()  # the two sides are within one layer
    scene = SplatCloud(p, n, radii, closed=True)
    o, d = camera_rays(eye, fov_y=50)
    t_true, _ = ray_box(o.astype(np.float64) / [1, 1, 0.01], d.astype(np.float64) / [1, 1, 0.01])
    truth = np.isfinite(t_true).reshape(H, W)
    interior = pixels_from_edge(truth) > 2
    res = scene.trace_surface(o, d, FULL)
    hit = (res.id >= 0).reshape(H, W)
    assert truth.sum() > 10000
    assert np.all(hit[truth & interior])
    # At the rim the two sides' discs overlap within one layer, so their fringe (about one
    # splat radius, ~4 pixels here) passes the far phase; nothing shows beyond it.
    assert not np.any(hit[~truth & (pixels_from_edge(truth) > 6)])
    got = res.normal.reshape(H, W, 3)[truth & interior]
    assert angle_deg(got, np.array(normal, dtype=float)).max() < 1e-3
    surface_z = (o + d * res.t[:, None])[:, 2].reshape(H, W)[truth & interior]
    np.testing.assert_allclose(surface_z, 0.01 * normal[2], atol=1e-4)


def height_field(n=120):
    g = np.linspace(-1, 1, n)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    z = 0.15 * np.sin(2 * x) * np.cos(1.5 * y)
    dzdx, dzdy = 0.3 * np.cos(2 * x) * np.cos(1.5 * y), -0.225 * np.sin(2 * x) * np.sin(1.5 * y)
    normals = np.column_stack([-dzdx, -dzdy, np.ones_like(x)])
    return np.column_stack([x, y, z]), normals / np.linalg.norm(normals, axis=1, keepdims=True)


def test_open_surface_is_fully_rendered_when_not_closed():
    """A height-field patch (an open surface, like terrain) with closed = False shows every
    pixel it covers, without holes. Marked closed by mistake, it still shows nearly all of
    it: no ray leaves an open surface, but the far phase only tests layers whose hit lies
    beyond the sampled surface (an edge's fringe), never one inside it (the paper's rule,
    which tests every layer, lost most of the patch)."""
    p, n = height_field()
    o, d = camera_rays((0.3, -2.2, 2.4), fov_y=45)
    open_scene, _ = cloud_scene(p, n, closed=False)
    res = open_scene.trace_surface(o, d, FULL)
    hit = (res.id >= 0).reshape(H, W)
    # The patch's footprint: what the general method covers, minus a pixel at its rim.
    general = (open_scene.trace_surface(o, d, Method.preset("GENERAL")).id >= 0).reshape(H, W)
    inner = general & (distance_transform_edt(general) > 2)
    assert inner.sum() > 20000
    assert np.all(hit[inner]), f"{(~hit[inner]).sum()} holes"
    wrongly_closed, _ = cloud_scene(p, n, closed=True)
    lost = wrongly_closed.trace_surface(o, d, FULL).id.reshape(H, W) < 0
    assert lost[inner].mean() < 0.01


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_secondary_rays_never_hit_the_splats_around_their_origin(scale):
    """Rays leaving the lit side of a sphere (towards a light, or mirrored) must escape: a
    convex object cannot shadow or reflect itself. With both wrong-hit rules -- excluding
    the splats that made the origin point (the layer's members) and ignoring back-facing
    discs -- no ray hits anything, at every scale. Without the exclusion, rays grazing the
    surface hit the neighbours they start on; with neither rule (the general method) most
    rays hit the splats they start from."""
    p, n = fibonacci_sphere(20000)
    scene, radii = cloud_scene(p * scale, n, closed=True)
    o, d = camera_rays(np.array([0.5, -4.0, 1.2]) * scale)
    prim = scene.trace_surface(o, d, FULL, members=True)
    ok = prim.id >= 0
    origin = o[ok] + d[ok] * prim.t[ok, None]
    nrm, members = prim.normal[ok], prim.members[ok]
    light = np.array([0.6, -0.3, 0.75]) / np.linalg.norm([0.6, -0.3, 0.75])
    mirror = d[ok] - 2 * np.einsum("ij,ij->i", d[ok], nrm)[:, None] * nrm
    general = Method.preset("GENERAL")
    for direction in (np.tile(light, (len(origin), 1)), mirror):
        leaving = np.einsum("ij,ij->i", direction, nrm) > 0
        ray_o, ray_d = origin[leaving], direction[leaving]
        assert leaving.sum() > 20000
        assert (scene.trace_surface(ray_o, ray_d, FULL, exclude=members[leaving]).id >= 0).sum() == 0
        assert (scene.trace_surface(ray_o, ray_d, general).id >= 0).mean() > 0.3
    grazing = np.einsum("ij,j->i", nrm, light) > 0
    grazing &= np.einsum("ij,j->i", nrm, light) < 0.02
    ray_o, ray_d = origin[grazing], np.tile(light, (grazing.sum(), 1))
    assert (scene.trace_surface(ray_o, ray_d, FULL).id >= 0).sum() > 0
    assert (scene.trace_surface(ray_o, ray_d, FULL, exclude=members[grazing]).id >= 0).sum() == 0


def test_rays_inside_an_object_swap_front_and_back():
    """A refracted ray travels inside the sphere: its next surface is the exit, a back-facing
    layer. With the roles swapped it finds the exit at the chord's end; treated as a ray
    from outside, wrong-hit elimination would discard the exit and the ray would escape."""
    p, n = fibonacci_sphere(20000)
    scene, _ = cloud_scene(p, n, closed=True)
    o, d = camera_rays((0.5, -4.0, 1.2))
    prim = scene.trace_surface(o, d, FULL, members=True)
    ok = prim.id >= 0
    entry = o[ok] + d[ok] * prim.t[ok, None]
    inward = d[ok]  # straight on, as with an index of refraction of 1
    exit_ = scene.trace_surface(entry, inward, FULL, inside=True, exclude=prim.members[ok])
    assert (exit_.id >= 0).all() and not np.any(exit_.front)
    # Chord length from an entry point on the unit sphere; where the ray enters at a slant
    # (more than ~17 degrees from the tangent plane) the flat discs' offset from the sphere
    # (r^2 / 2R ~ 5e-4, over the cosine) stays below 0.01.
    expected = -2 * np.einsum("ij,ij->i", entry, inward)
    steep = -np.einsum("ij,ij->i", prim.normal[ok], inward) > 0.3
    np.testing.assert_allclose(exit_.t[steep], expected[steep], atol=0.01)
    escaped = scene.trace_surface(entry, inward, FULL, inside=False, exclude=prim.members[ok])
    assert (escaped.id < 0).mean() > 0.95


def test_method_validation():
    with pytest.raises(ValueError, match="position"):
        Method(position="MIDDLE")
    with pytest.raises(ValueError, match="epsilon"):
        Method(epsilon=-1)
    with pytest.raises(ValueError, match="preset"):
        Method.preset("BEST")
    scene = SplatCloud([[0, 0, 0]], [[0, 0, 1]], [1.0])
    with pytest.raises(ValueError, match="exclude"):
        scene.trace_surface([[0, 0, 1]], [[0, 0, -1]], exclude=np.zeros(3, np.int32))
    with pytest.raises(TypeError):
        scene._scene.trace_surface(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), 0.0, 1.0, "FULL",
                                   np.empty(1, np.float32), np.empty(1, np.int32), np.empty(1, np.uint8),
                                   np.empty((1, 3), np.float32), np.empty((1, 3), np.float32))


def test_the_switch_table_names_the_method_fields_and_the_ab_notes():
    """Every switch is a Method field of its name (or chooses the position rule), its Blender
    property is use_<name>, the A/B notes have a label for every field, and switch values
    and methods convert both ways."""
    method_fields = {f.name: f for f in fields(Method)}
    assert len({s.name for s in SWITCHES}) == len(SWITCHES)
    for switch in SWITCHES:
        assert switch.prop == "use_" + switch.name and switch.label and switch.description
        assert switch.field in method_fields
        assert switch.field == switch.name or switch.field == "position"
        assert {switch.on, switch.off} <= ({True, False} if switch.field == switch.name else set(POSITION_RULES))
    assert set(ab._LABELS) == set(method_fields) | {"radius_factor"}
    for preset in PRESETS:
        method = Method.preset(preset)
        assert replace(method, **switch_fields(switches_of(method))) == method
    # The near phase decides the position whenever it is on; the nearest centre only without it.
    both_off = dict.fromkeys((s.name for s in SWITCHES), False)
    assert switch_fields({**both_off, "near_phase": True, "nearest_centre": True})["position"] == "NEAR_PHASE"
    assert switch_fields({**both_off, "nearest_centre": True})["position"] == "NEAREST_CENTRE"
    assert switch_fields(both_off)["position"] == "FIRST"
    with pytest.raises(KeyError, match="far_phase"):
        switch_fields({k: v for k, v in both_off.items() if k != "far_phase"})


def test_the_core_reads_the_method_by_field_name():
    """The binding takes any object with Method's fields, and names a field it misses or
    cannot use."""
    cloud = SplatCloud(*cube_cloud(8), np.full(6 * 64, 0.2), closed=True)
    o, d = camera_rays((2.5, -3.0, 2.0))
    trace = lambda method: cloud.trace_surface(o, d, method)  # noqa: E731 - SplatCloud passes it as it is
    for method in (FULL, Method.preset("GENERAL"), Method.preset("NEAREST_CENTRE", kernel="SMOOTH", epsilon=2.0)):
        a, b = trace(method), trace(SimpleNamespace(**asdict(method)))
        assert all(np.array_equal(x, y) for x, y in zip(a, b) if x is not None)
    for name in asdict(FULL):
        with pytest.raises(TypeError, match=f"method has no field '{name}'"):
            trace(SimpleNamespace(**{k: v for k, v in asdict(FULL).items() if k != name}))
    bad = {"epsilon": ("1.0", TypeError), "crease_angle": (None, TypeError), "position": ("MIDDLE", ValueError),
           "kernel": (1, ValueError)}
    for name, (value, error) in bad.items():
        with pytest.raises(error, match=f"'{name}'"):
            trace(SimpleNamespace(**{**asdict(FULL), name: value}))


def test_render_uses_the_method_and_agrees_with_trace_surface(cube):
    scene, o, d, truth, _, _ = cube
    cam = Camera.look_at((2.5, -4.0, 3.0), (0, 0, 0), fov_y=35.0, aspect=W / H)
    img = scene.render(cam, W, H, method=FULL)
    surf = scene.trace_surface(o, d, FULL)
    # render() makes its rays in double precision, Camera.rays() in numpy and then float32:
    # a few rays along an edge see a different member set.
    assert ((img.rgba[..., 3].ravel() == 1.0) != (surf.id >= 0)).sum() <= 3
    hit = (surf.id >= 0) & (img.rgba[..., 3].ravel() == 1.0)
    differ = np.abs(img.normal.reshape(-1, 3)[hit] - surf.normal[hit]).max(axis=1) > 1e-4
    assert differ.mean() < 0.005
