"""The environment light's distribution (native/shade/environment.h), checked against values
computed here independently: its density integrates to 1 over the sphere, the directions it
draws are distributed as that density says, the density is proportional to luminance where
the image is smooth, and the lookup is Cycles' equirectangular orientation."""
import numpy as np
import pytest

from splat_tracer import _core


def _image(seed=1, w=64, h=32):
    """A smooth sky with a small bright sun: the case importance sampling is for."""
    rng = np.random.default_rng(seed)
    img = (0.2 + 0.1 * rng.random((h, w, 3))).astype(np.float32)
    img[20, 10] = (400.0, 350.0, 300.0)  # the sun: one pixel, most of the power
    return img


def _run(img, uniforms, directions):
    n, m = len(uniforms), len(directions)
    out_d = np.zeros((n, 3), np.float32)
    out_pdf = np.zeros(n, np.float32)
    out_pdf_at = np.zeros(m, np.float32)
    out_rad = np.zeros((m, 3), np.float32)
    _core._environment_map(img, np.ascontiguousarray(uniforms, np.float32),
                           np.ascontiguousarray(directions, np.float32), out_d, out_pdf, out_pdf_at, out_rad)
    return out_d, out_pdf, out_pdf_at, out_rad


def _grid(nu=2048, nv=1024):
    """Directions at the centres of a fine (u, v) grid and the solid angle of each cell."""
    u = (np.arange(nu) + 0.5) / nu
    v = (np.arange(nv) + 0.5) / nv
    uu, vv = np.meshgrid(u, v)
    phi, el = (0.5 - uu) * 2 * np.pi, (vv - 0.5) * np.pi
    d = np.stack([np.cos(el) * np.cos(phi), np.cos(el) * np.sin(phi), np.sin(el)], -1).reshape(-1, 3)
    cell = (2 * np.pi / nu) * (np.pi / nv) * np.cos(el).ravel()
    return d, cell


def test_pdf_integrates_to_one():
    d, cell = _grid()
    _, _, pdf_at, _ = _run(_image(), np.zeros((0, 2)), d)
    total = float(np.sum(pdf_at * cell))
    assert abs(total - 1.0) < 2e-3, total


def test_samples_follow_the_pdf():
    img = _image()
    rng = np.random.default_rng(7)
    u = rng.random((200_000, 2)).astype(np.float32)
    u = np.minimum(u, np.float32(1 - 2 ** -24))
    dirs, pdf, pdf_again, _ = _run(img, u, rng.standard_normal((0, 3)))
    assert np.all(pdf > 0)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-5)
    # The density sample() reports is the one pdf() gives at the drawn direction (but for
    # draws on a pixel's edge, which float rounding may put in the neighbour: < 0.1 %).
    _, _, pdf_at, _ = _run(img, np.zeros((0, 2)), dirs)
    assert np.mean(~np.isclose(pdf_at, pdf, rtol=2e-3)) < 1e-3
    # A histogram of the draws over 8 x 4 cells of (u, v) against the integral of the pdf there.
    uu = 0.5 - np.arctan2(dirs[:, 1], dirs[:, 0]) / (2 * np.pi)
    vv = 0.5 + np.arcsin(np.clip(dirs[:, 2], -1, 1)) / np.pi
    counts, _, _ = np.histogram2d(vv, uu, bins=(4, 8), range=((0, 1), (0, 1)))
    d, cell = _grid(512, 256)
    _, _, p, _ = _run(img, np.zeros((0, 2)), d)
    expected = (p * cell).reshape(256, 512).reshape(4, 64, 8, 64).sum(axis=(1, 3)) * len(u)
    sigma = np.sqrt(expected) + 1
    assert np.all(np.abs(counts - expected) < 5 * sigma), (counts, expected)
    # Most draws go to the sun (its 3x3 support holds most of the weighted luminance).
    assert counts.max() > 0.8 * len(u)


def test_lookup_orientation_is_cycles():
    """+x is the image's middle column (u = 0.5), +y a quarter to the left (u = 0.25), up the
    top row: Cycles' direction_to_equirectangular."""
    h, w = 32, 64
    img = np.zeros((h, w, 3), np.float32)
    img[h // 2 - 1: h // 2 + 1, w // 2 - 1: w // 2 + 1] = (1, 0, 0)  # around +x
    img[h // 2 - 1: h // 2 + 1, w // 4 - 1: w // 4 + 1] = (0, 1, 0)  # around +y
    img[-1, :] = (0, 0, 1)  # the zenith row
    _, _, _, rad = _run(img, np.zeros((0, 2)), np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0]], np.float32))
    assert np.allclose(rad, [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]], atol=1e-5)


def test_black_image_is_not_sampled():
    img = np.zeros((8, 16, 3), np.float32)
    _, pdf, pdf_at, _ = _run(img, np.full((4, 2), 0.5), np.array([[0, 0, 1.0]], np.float32))
    assert np.all(pdf == 0) and np.all(pdf_at == 0)


@pytest.mark.parametrize("bad", [np.full((8, 16, 3), np.nan, np.float32), np.full((8, 16, 3), -1, np.float32),
                                 np.zeros((1, 16, 3), np.float32)])
def test_bad_images_are_refused(bad):
    with pytest.raises(ValueError):
        _run(bad, np.zeros((0, 2)), np.zeros((0, 3)))


# --------------------------------------------------------------------------------------
# The environment as a light in a render (plain core, no Blender).

def _env_scene():
    """A floor and a sphere cloud under the sun-spot sky of _image() (no lamp)."""
    from splat_tracer.render.scene import Instance, Mesh, RenderScene
    from splat_tracer.render.shading import Material, World
    from splat_tracer.render.splats import SplatCloud
    from geometry import sphere_cloud

    p, n, r = sphere_cloud(4000, radius=0.4)
    floor = Mesh([(-5, -5, 0), (5, -5, 0), (5, 5, 0), (-5, 5, 0)], np.array([(0, 1, 2), (0, 2, 3)]))
    lambert = Material(base_colour=(0.8,) * 3, specular_level=0.0, roughness=1.0)
    world = World(environment=_image())
    return RenderScene([Instance(floor, materials=(lambert,)), Instance(SplatCloud(p + [0, 0, 0.5], n, r),
                                                                        materials=(lambert,))], (), world)


def _env_render(scene, strategy, samples, seed=0):
    from splat_tracer.render.camera import Camera
    from splat_tracer.render.shading import RenderSettings

    cam = Camera.look_at((0.0, -3.0, 1.8), (0.0, 0.2, 0.3), up=(0, 0, 1), fov_y=50, aspect=4 / 3)
    res = scene.render(cam, 32, 24, RenderSettings(samples=samples, diffuse_bounces=1, seed=seed,
                                                   mesh_light_strategy=strategy))
    return res.passes["Combined"][..., :3].astype(np.float64), res


def test_light_bsdf_and_mis_agree_and_importance_sampling_cuts_the_noise():
    """Shadow rays towards the environment only, BSDF rays only and both weighed by MIS are
    three unbiased estimators: their means agree within 3 % (measured: 16 samples LIGHT 0.4194,
    BSDF 0.4013, MIS 0.4154; 1024-sample MIS 0.4141). At equal samples (16), the error against
    the 1024-sample MIS reference is several times smaller with the environment sampled (MIS)
    than without (BSDF: the sun found by chance). Measured mean absolute error: MIS 0.040,
    BSDF 0.378 (9.5x), LIGHT alone 0.134 (the wide sky is what BSDF rays find best)."""
    scene = _env_scene()
    reference, _ = _env_render(scene, "MIS", 1024)
    images = {s: _env_render(scene, s, 16, seed=1)[0] for s in ("LIGHT", "BSDF", "MIS")}
    means = {k: v.mean() for k, v in images.items()}
    print({k: round(v, 4) for k, v in means.items()}, "reference", round(reference.mean(), 4))
    long_bsdf = _env_render(scene, "BSDF", 1024)[0]
    assert abs(long_bsdf.mean() / reference.mean() - 1) < 0.03
    for k in ("LIGHT", "MIS"):
        assert abs(means[k] / reference.mean() - 1) < 0.03, (k, means)
    error = {k: np.abs(v - reference).mean() for k, v in images.items()}
    print("mean absolute error at 16 samples", {k: round(v, 4) for k, v in error.items()})
    assert error["MIS"] * 4 < error["BSDF"]
    assert error["MIS"] <= error["LIGHT"] * 1.2


def test_camera_rays_see_the_camera_image_and_the_light_is_the_other():
    """World.camera_environment: what camera rays see; the floor is lit by `environment`."""
    from splat_tracer.render.shading import World

    scene = _env_scene()
    lit, _ = _env_render(scene, "MIS", 16)
    green = np.zeros((8, 16, 3), np.float32)
    green[..., 1] = 0.5
    scene.world = World(environment=_image(), camera_environment=green)
    both, _ = _env_render(scene, "MIS", 16)
    sky = np.isclose(both, (0, 0.5, 0)).all(-1)
    assert sky.sum() > 50  # the top rows see the backdrop
    # The same light everywhere else: pixels differ only on the sky and its filtered edge.
    from scipy.ndimage import binary_dilation
    differ = ~np.isclose(lit, both).all(-1)
    assert not (differ & ~binary_dilation(sky, iterations=2)).any()  # the filter: 3 px wide


def test_world_ray_visibility_applies_to_the_environment():
    """World > Ray Visibility: hidden from diffuse rays, the environment lights no diffuse
    surface (neither by shadow rays towards it nor by bounces); hidden from the camera, the
    background is black. Measured: floor and cloud exactly 0 (pure diffuse, no lamp)."""
    from splat_tracer.render.shading import World

    scene = _env_scene()
    seen, _ = _env_render(scene, "MIS", 4)
    scene.world = World(environment=_image(), visibility=frozenset({"camera", "glossy", "transmission"}))
    no_diffuse, _ = _env_render(scene, "MIS", 4)
    from scipy.ndimage import binary_dilation
    sky = np.isclose(no_diffuse, seen).all(-1) & (no_diffuse.sum(-1) > 0)
    surfaces = ~binary_dilation(sky, iterations=2)  # the filter is 3 px wide
    assert sky.sum() > 50 and surfaces.sum() > 300
    assert np.all(no_diffuse[surfaces] == 0) and seen[surfaces].min() > 0.01
    scene.world = World(environment=_image(), visibility=frozenset({"diffuse", "glossy", "transmission"}))
    no_camera, _ = _env_render(scene, "MIS", 4)
    assert np.all(no_camera[sky] == 0) and np.array_equal(no_camera[surfaces], seen[surfaces])


def test_a_changed_image_is_never_served_from_the_cores_cache():
    """The core keeps the last environment maps by content (a viewport re-renders the same
    world many times): the same image renders the same, an image changed in place (same array,
    same shape) renders with its new content."""
    from splat_tracer.render.shading import World

    scene = _env_scene()
    image = _image()
    scene.world = World(environment=image)
    first, _ = _env_render(scene, "MIS", 4)
    again, _ = _env_render(scene, "MIS", 4)
    assert np.array_equal(first, again)
    image[20, 10] = 0.0  # the sun taken out of the same array
    scene.world = World(environment=image)
    dark, _ = _env_render(scene, "MIS", 4)
    assert dark.mean() < 0.6 * first.mean()  # measured 0.21 against 0.42: the sun is most of the light
