"""The world as an environment (issue 24, item 2) through Blender, side by side with Cycles.

One scene for both engines: a scan (a splat-cloud sphere) over a grey mesh floor, no lamp,
lit only by an HDRI -- a small synthetic equirectangular float image (64 x 32, written to an
EXR in a temporary folder) of a blue sky, a brown ground and a 2 x 2 pixel sun 50 degrees up
-- seen at 160 x 120 with 64 samples (Cycles: CPU, no denoising, no adaptive sampling). The
regions are Cycles' own, from its Object Index and its floor's brightness: "lit floor", "in
the shadow" (the floor below half the lit floor's median, eroded), "sky" (index 0).

Tolerances (measured with bpy 5.0.1; each shown to reject a wrong render below):
- REGION_RTOL = 0.08: mean colour of the lit floor and the sky against Cycles' (measured: lit
  floor within 0.1 %, the sky exact); SHADOW_RTOL = 0.15 in the shadow, lit by the sky alone
  (measured 0.275 here, 0.245 in Cycles: +12 %, which the uniform world of the same scene does
  not show -- 0.391 and 0.389 -- so it is the occluder's shape, Cycles rendering the cloud's
  points as spheres).
- SHADOW_IOU = 0.6: the overlap (intersection over union) of the two engines' shadow masks
  (ours thresholded as Cycles'); the HDRI mirrored left-right, or a Mapping rotation
  ignored, moves the shadow and leaves an overlap below MOVED_IOU = 0.3.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from blender_helpers import add_camera
from test_scene_export import INDEX, erode, iou, render
from test_shadow_catcher import FLOOR, SCAN, scan_on_floor

W, H = 160, 120
SAMPLES = 64
REGION_RTOL, SHADOW_RTOL, SHADOW_IOU, MOVED_IOU = 0.08, 0.15, 0.6, 0.3
SKY_LIT_RTOL, SKY_SHADOW_RTOL, SKY_GROUND_RTOL = 0.04, 0.4, 0.02  # see the Sky Texture's test
SKY, GROUND = (0.25, 0.32, 0.45), (0.12, 0.09, 0.06)
SUN_U, SUN_V = 0.3, 0.5 + 50 / 180  # the sun's image position: azimuth 72 degrees, 50 up
SUN = 150.0  # radiance of its 2 x 2 pixels: ~2.3 irradiance on the floor, ~7x the sky's


def hdri(mirrored=False) -> np.ndarray:
    """The synthetic HDRI, (32, 64, 4), row 0 at the bottom (Blender's pixel order)."""
    h, w = 32, 64
    img = np.zeros((h, w, 4), np.float32)
    img[..., 3] = 1
    img[h // 2:, :, :3] = SKY
    img[:h // 2, :, :3] = GROUND
    # Brighter towards the zenith, so that a wrong orientation shows in the sky too.
    img[h // 2:, :, :3] *= np.linspace(0.8, 1.3, h // 2)[:, None, None]
    x, y = int(SUN_U * w), int(SUN_V * h)
    img[y:y + 2, x:x + 2, :3] = SUN
    if mirrored:
        img = img[:, ::-1].copy()
    return img


def save_hdri(bpy, path, mirrored=False):
    """The HDRI written as a float EXR (top row first, as files are) and loaded as Blender
    loads an HDRI: scene-linear floats."""
    import OpenEXR

    rgba = np.ascontiguousarray(hdri(mirrored)[::-1])
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {c: np.ascontiguousarray(rgba[..., i]) for i, c in enumerate("RGBA")}
    with OpenEXR.File(header, channels) as f:
        f.write(str(path))
    image = bpy.data.images.load(str(path))
    image.colorspace_settings.name = "Linear Rec.709"
    return image


def _scene(bpy, folder):
    scene, floor, scan = scan_on_floor(bpy)
    add_camera(bpy, scene, (0, -6, 3.5), (math.radians(66), 0, 0))
    world = scene.world = bpy.data.worlds.new("HDRI")
    nodes, links = world.node_tree.nodes, world.node_tree.links
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = save_hdri(bpy, folder / "sky.exr")
    mapping = nodes.new("ShaderNodeMapping")
    coords = nodes.new("ShaderNodeTexCoord")
    links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    background = nodes["Background"]
    links.new(env.outputs["Color"], background.inputs["Color"])
    # For the Is Camera Ray case: a green backdrop for camera rays, the HDRI for the rest.
    backdrop = nodes.new("ShaderNodeBackground")
    backdrop.inputs["Color"].default_value = (0.1, 0.5, 0.1, 1)
    mix = nodes.new("ShaderNodeMixShader")
    path = nodes.new("ShaderNodeLightPath")
    links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
    links.new(background.outputs[0], mix.inputs[1])
    links.new(backdrop.outputs[0], mix.inputs[2])
    # For the Sky Texture case: the default Nishita sky with its sun 30 degrees up, turned 120
    # degrees (neither is where the model was measured).
    sky = nodes.new("ShaderNodeTexSky")
    sky.sun_elevation, sky.sun_rotation = math.radians(30), math.radians(120)
    c = scene.cycles
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling = SAMPLES, "CPU", False, False
    scene.splat_tracer.samples = SAMPLES
    scene.view_layers[0].use_pass_object_index = True
    return scene, dict(env=env, sky=sky, mapping=mapping, mix=mix, background=background,
                       output=nodes["World Output"], mirrored=save_hdri(bpy, folder / "mirrored.exr", True),
                       plain=env.image, scan=scan)


SKY_DEFAULTS = dict(sky_type="MULTIPLE_SCATTERING", sun_elevation=30.0, sun_disc=True, aerosol_density=1.0)
# The legacy models' Sun Direction: the sun 30 degrees up, turned 120 (as the default case's).
LEGACY_SUN = (math.sin(math.radians(120)) * math.cos(math.radians(30)),
              math.cos(math.radians(120)) * math.cos(math.radians(30)), math.sin(math.radians(30)))
LEGACY_SKIES = {"sky preetham": dict(sky_type="PREETHAM", turbidity=3.0, sun_direction=LEGACY_SUN),
                "sky hosek-wilkie": dict(sky_type="HOSEK_WILKIE", turbidity=3.0, ground_albedo=0.5,
                                         sun_direction=LEGACY_SUN),
                "sky hosek-wilkie albedo 0": dict(sky_type="HOSEK_WILKIE", turbidity=3.0, ground_albedo=0.0,
                                                  sun_direction=LEGACY_SUN)}
CASES = {**{k: dict(sky=v) for k, v in LEGACY_SKIES.items()},
"plain": {}, "mirrored": dict(mirrored=True), "rotated": dict(rotation=90.0),
         "camera_ray": dict(camera_ray=True), "sky": dict(sky={}),
         "sky 15": dict(sky=dict(sun_elevation=15.0)), "sky 60": dict(sky=dict(sun_elevation=60.0)),
         "sky aerosol 5": dict(sky=dict(aerosol_density=5.0)), "sky no disc": dict(sky=dict(sun_disc=False)),
         "sky 15 bare": dict(sky=dict(sun_elevation=15.0), scan=False),
         "sky 15 bare no disc": dict(sky=dict(sun_elevation=15.0, sun_disc=False), scan=False)}


@pytest.fixture(scope="module")
def renders(blender, tmp_path_factory):
    folder = tmp_path_factory.mktemp("world")
    scene, n = _scene(blender, folder)
    links = scene.world.node_tree.links
    cache = {}

    def configure(case):
        cfg = CASES[case]
        n["env"].image = n["mirrored"] if cfg.get("mirrored") else n["plain"]
        n["mapping"].inputs["Rotation"].default_value = (0, 0, math.radians(cfg.get("rotation", 0.0)))
        n["scan"].hide_render = not cfg.get("scan", True)
        source = n["mix"] if cfg.get("camera_ray") else n["background"]
        links.new(source.outputs[0], n["output"].inputs["Surface"])
        links.new(n["sky" if "sky" in cfg else "env"].outputs["Color"], n["background"].inputs["Color"])
        settings = dict(SKY_DEFAULTS, **cfg.get("sky", {}))
        n["sky"].sun_elevation = math.radians(settings.pop("sun_elevation"))
        for k, v in settings.items():
            setattr(n["sky"], k, v)

    def get(case, engine="SPLAT_TRACER"):
        if (case, engine) not in cache:
            configure(case)
            scene.render.engine = engine
            cache[case, engine] = render(blender, scene, folder / f"{case}_{engine}.exr", (W, H))["ViewLayer"]
        return cache[case, engine]
    get.configure = configure
    return get


def floor_masks(out, reference=None):
    """(lit floor, shadow) of a render; the floor's pixels from `reference`'s Object Index
    (Cycles'), the threshold half the lit floor's median brightness."""
    reference = out if reference is None else reference
    floor = erode(reference[INDEX] == FLOOR, 2)
    lum = out["Combined"][..., :3].mean(-1)
    median = np.median(lum[floor])
    shadow = floor & (lum < 0.5 * median)
    lit = floor & ~shadow & (lum > 0.8 * median)
    return erode(lit, 1), erode(shadow, 1)


def region_means(out, masks) -> dict:
    return {k: out["Combined"][..., :3][m].mean(0) for k, m in masks.items()}


def close(a, b, rtol=REGION_RTOL) -> bool:
    return bool(np.all(np.abs(a - b) <= rtol * np.maximum(np.abs(b), 0.05)))


def test_an_hdri_with_a_sun_lights_the_scene_as_in_cycles(renders):
    cycles, ours = renders("plain", "CYCLES"), renders("plain")
    lit, shadow = floor_masks(cycles)
    masks = {"lit floor": lit, "shadow": shadow, "sky": erode(cycles[INDEX] == 0, 2)}
    assert all(m.sum() > 100 for m in masks.values()), {k: int(m.sum()) for k, m in masks.items()}
    mc, mo = region_means(cycles, masks), region_means(ours, masks)
    print({k: (mo[k].round(4).tolist(), mc[k].round(4).tolist()) for k in masks})
    for k in masks:
        assert close(mo[k], mc[k], SHADOW_RTOL if k == "shadow" else REGION_RTOL), (k, mo[k], mc[k])
    # The shadow where Cycles has it; the mirrored HDRI's elsewhere.
    _, ours_shadow = floor_masks(ours, cycles)
    print("shadow IoU", iou(ours_shadow, shadow))
    assert iou(ours_shadow, shadow) > SHADOW_IOU
    _, mirrored_shadow = floor_masks(renders("mirrored"), cycles)
    print("mirrored HDRI's shadow IoU", iou(mirrored_shadow, shadow))
    assert iou(mirrored_shadow, shadow) < MOVED_IOU
    # The sun is a sharp light: the shadow is deep (a uniform world of the same power, the
    # engine's former approximation, gives no shadow at all).
    assert mo["shadow"].mean() < 0.5 * mo["lit floor"].mean()


def test_a_mapping_rotation_turns_the_shadow_as_in_cycles(renders):
    cycles, ours = renders("rotated", "CYCLES"), renders("rotated")
    _, shadow = floor_masks(cycles)
    _, ours_shadow = floor_masks(ours, cycles)
    _, unrotated = floor_masks(renders("plain", "CYCLES"))
    print("rotated shadow IoU", iou(ours_shadow, shadow), "against the unrotated", iou(unrotated, shadow))
    assert shadow.sum() > 50
    assert iou(ours_shadow, shadow) > SHADOW_IOU
    assert iou(unrotated, shadow) < MOVED_IOU  # ignoring the rotation would fail


def test_is_camera_ray_shows_one_backdrop_and_lights_with_another(renders):
    cycles, ours = renders("camera_ray", "CYCLES"), renders("camera_ray")
    lit, shadow = floor_masks(cycles)
    masks = {"lit floor": lit, "shadow": shadow, "sky": erode(cycles[INDEX] == 0, 2)}
    mc, mo = region_means(cycles, masks), region_means(ours, masks)
    print({k: (mo[k].round(4).tolist(), mc[k].round(4).tolist()) for k in masks})
    assert np.allclose(mc["sky"], (0.1, 0.5, 0.1), rtol=0.01)
    for k in masks:
        assert close(mo[k], mc[k], SHADOW_RTOL if k == "shadow" else REGION_RTOL), (k, mo[k], mc[k])
    # The floor lit by the HDRI, as without the trick (the green backdrop would light it green).
    plain = region_means(renders("plain"), masks)
    assert close(mo["lit floor"], plain["lit floor"], 0.03)
    assert not close(plain["sky"], mc["sky"])


@pytest.mark.parametrize("case", ["sky", "sky 15", "sky 60", "sky aerosol 5", "sky no disc"])
def test_the_sky_texture_lights_the_floor_and_casts_the_sun_shadow_as_in_cycles(renders, case):
    """The Sky Texture (Multiple Scattering, Blender's default) from its model
    (render/sky.py), the sun 15, 30 or 60 degrees up and turned 120, or with five times the
    aerosols, or without its disc. Measured, ours against Cycles (R, G, B):
    - lit floor: 30 degrees -1.2, -1.1, -0.9 % (the fitted model of before: -1.9, -2.2,
      -2.6 %); 15 degrees -3.3, -2.8, -1.8 %; 60 degrees -0.3, -0.3, -0.2 %; aerosols x5
      -1.4, -1.2, -1.0 %; without the disc (the sky alone) +0.1, +0.2, +0.3 %. So the sky's
      light agrees and the sun's is 1.4 % (30 degrees) to 4 % (15) short of Cycles', growing
      with the air mass; the disc's power as the model gives it (limb mean x centre radiance
      x solid angle) is checked to 1e-4 against the disc integrated texel by texel. The gap
      is the scan's, not the sun's: with the scan hidden the floor agrees within 0.3 % (the
      test below), the scan adding 3.8 % to this floor in ours and 7.2 % in Cycles at 15
      degrees (the sunlit cloud's light sent onto the floor; Cycles draws its points as
      spheres), reddest and largest for a low sun whose light grazes the floor but meets the
      cloud's side square on.
    - the ground below the horizon: within 0.4 % (before: +130, +69, +29 %).
    - the shadow's outline overlaps 85 % (before 86 %); in the shadow, lit by the sky alone,
      +28, +15, +7 % at 30 degrees (before +34, +17, +7 %), up to +34 % (red) at 60: the
      occluder -- the same scene under an HDRI is +12 % there (SHADOW_RTOL), Cycles
      rendering the cloud's points as spheres; the penumbra's red sunlight weighs on the
      mask's mean.
    SKY_LIT_RTOL 0.04, SKY_SHADOW_RTOL 0.4, SKY_GROUND_RTOL 0.02 (before 0.05, 0.5, 1.5)."""
    cycles, ours = renders(case, "CYCLES"), renders(case)
    lit, shadow = floor_masks(cycles)
    disc = CASES[case]["sky"].get("sun_disc", True)
    masks = {"lit floor": lit, "ground": erode(cycles[INDEX] == 0, 2)}
    if disc:
        masks["shadow"] = shadow
    assert all(m.sum() > 100 for m in masks.values()), {k: int(m.sum()) for k, m in masks.items()}
    mc, mo = region_means(cycles, masks), region_means(ours, masks)
    print(case, {k: (mo[k].round(3).tolist(), mc[k].round(3).tolist()) for k in masks})
    assert close(mo["lit floor"], mc["lit floor"], SKY_LIT_RTOL)
    assert close(mo["ground"], mc["ground"], SKY_GROUND_RTOL)
    if disc:
        _, ours_shadow = floor_masks(ours, cycles)
        print(case, "sky shadow IoU", iou(ours_shadow, shadow))
        assert close(mo["shadow"], mc["shadow"], SKY_SHADOW_RTOL)
        assert iou(ours_shadow, shadow) > SHADOW_IOU
        # The fitted model of before (the default atmosphere whatever the settings) is far off:
        # five times the aerosols brighten the ground below the horizon threefold.
        if case == "sky aerosol 5":
            default = region_means(renders("sky", "CYCLES"), {"ground": masks["ground"]})["ground"]
            assert not close(default, mc["ground"], 10 * SKY_GROUND_RTOL)
    else:
        # Without the disc the sky alone lights the floor: no sun shadow, far darker.
        with_disc = region_means(renders("sky", "CYCLES"), {"lit floor": lit})["lit floor"]
        assert np.all(mc["lit floor"] < 0.5 * with_disc)


# The floor alone (the scan hidden) under the sky with its sun 15 degrees up: measured ours
# against Cycles -0.18, -0.15, -0.10 % (30 degrees: +0.31, +0.28, +0.22 %); with the scan the
# same floor is -3.3, -2.8, -1.8 % (30 degrees: -1.2, -1.1, -0.9 %).
SKY_BARE_RTOL = 0.01


def test_the_sky_sun_lights_a_bare_floor_as_in_cycles(renders):
    """The Sky Texture's sun lights the floor as Cycles' does once the scan is hidden: the
    1-4 % the floor beside the scan is short of Cycles' (the test above) is the light the scan
    sends onto the floor (at 15 degrees the scan adds 3.8 % to this floor in ours, 7.2 % in
    Cycles, which draws the cloud's points as spheres: the shadow's difference too), not the
    sun's. The sun's disc without its limb darkening (its power / 0.8) would be outside."""
    cycles, ours = renders("sky 15 bare", "CYCLES"), renders("sky 15 bare")
    lit, _ = floor_masks(cycles)
    assert lit.sum() > 1000
    mc, mo = region_means(cycles, {"f": lit})["f"], region_means(ours, {"f": lit})["f"]
    no_disc = region_means(renders("sky 15 bare no disc"), {"f": lit})["f"]
    unlimbed = no_disc + (mo - no_disc) / 0.8  # LIMB_MEAN: the disc's mean over its centre
    print("bare floor", mo.round(3).tolist(), mc.round(3).tolist(), "without limb darkening", unlimbed.round(3).tolist())
    assert close(mo, mc, SKY_BARE_RTOL)
    assert not close(unlimbed, mc, SKY_BARE_RTOL)


# Measured (bpy 5.0.1; ours against Cycles, R, G, B): Preetham's lit floor +0.2, +0.4, +0.4 %,
# Hosek-Wilkie's 0.0, +0.2, +0.2 %; the sky behind the scan equal to 4 digits. The wrong models
# are far outside: Hosek-Wilkie for Preetham -85 %; its Ground Albedo ignored -19 % (floor),
# -31 % (sky).
LEGACY_LIT_RTOL, LEGACY_SKY_RTOL = 0.02, 0.01


@pytest.mark.parametrize("case, wrong", [("sky preetham", "sky hosek-wilkie"),
                                         ("sky hosek-wilkie", "sky hosek-wilkie albedo 0")])
def test_the_legacy_sky_models_light_the_floor_as_in_cycles(renders, case, wrong):
    """Preetham and Hosek-Wilkie (turbidity 3, the sun 30 degrees up and turned 120; no sun
    disc in these models, the bright sky around the sun casts a soft shadow): the lit floor
    and the sky seen behind the scan (the horizon's colour below it) against Cycles'. A wrong
    model is outside the tolerance: the other model, or Hosek-Wilkie's Ground Albedo ignored
    (0 instead of 0.5)."""
    cycles, ours = renders(case, "CYCLES"), renders(case)
    lit, _ = floor_masks(cycles)
    masks = {"lit floor": lit, "sky": erode(cycles[INDEX] == 0, 2)}
    assert all(m.sum() > 100 for m in masks.values()), {k: int(m.sum()) for k, m in masks.items()}
    mc, mo = region_means(cycles, masks), region_means(ours, masks)
    mw = region_means(renders(wrong, "CYCLES"), masks)
    print(case, {k: (mo[k].round(4).tolist(), mc[k].round(4).tolist(), mw[k].round(4).tolist()) for k in masks})
    assert close(mo["lit floor"], mc["lit floor"], LEGACY_LIT_RTOL)
    assert close(mo["sky"], mc["sky"], LEGACY_SKY_RTOL)
    assert not close(mw["lit floor"], mc["lit floor"], LEGACY_LIT_RTOL)
    assert not close(mw["sky"], mc["sky"], LEGACY_SKY_RTOL)


def test_the_world_bake_is_cached_and_a_plain_background_is_not_baked(blender, renders):
    from blender_helpers import extension_module

    renders("plain")
    renders.configure("plain")
    world_module = extension_module("blender.export.world")
    shading_module = extension_module("blender.export.shading")
    scene = blender.context.scene
    report = extension_module("render.shading").Report()
    w = shading_module.world_of(scene, report)
    assert w.environment is not None and w.environment.shape == (32, 64, 3)
    assert w.camera_environment is None
    assert shading_module.world_of(scene, report).environment is w.environment  # the same content: no new bake
    scene.world.node_tree.nodes["Mapping"].inputs["Rotation"].default_value[2] = 0.5
    assert shading_module.world_of(scene, report).environment is not w.environment  # a change: baked again
    scene.world.node_tree.nodes["Mapping"].inputs["Rotation"].default_value[2] = 0.0
    # The baked image is the HDRI itself, pixel for pixel (no mapping: Generated is the direction).
    assert np.allclose(w.environment, hdri()[..., :3], rtol=1e-5)
    # A plain Background keeps the uniform path: nothing baked.
    hdri_world, scene.world = scene.world, blender.data.worlds.new("Plain")
    try:
        plain = shading_module.world_of(scene, report)
        assert plain.environment is None and plain.radiance() == pytest.approx((0.05, 0.05, 0.05), abs=0.01)
    finally:
        scene.world = hdri_world


# --------------------------------------------------------------------------------------
# The bake against Cycles' own evaluation of the world: the world alone, seen by an
# equirectangular panoramic camera from the origin (both engines render those), pixel by pixel.

PANO_W, PANO_H = 256, 128
# A pixel is off when a channel differs by more than PANO_TOL x the image's mean; at most
# PANO_OFF of them may be, and the median difference is below PANO_MEDIAN x the mean.
# Measured: 1.0 %, 1.3 %, 0.7 % of the pixels off (on the sun's and the horizon's edges, where
# 4 samples of the pixel filter differ), median 1e-4, 1.2e-3 (Closest's steps), 1e-7 x the
# mean. A wrong variant is outside both: the image read as equirectangular instead of as a
# mirror ball 6 % off, median 4.8e-3; the mapping ignored 30 % off, median 2.0e-2.
PANO_TOL, PANO_OFF, PANO_MEDIAN = 0.3, 0.02, 0.002


def _pano_scene(bpy, folder):
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    add_camera(bpy, scene, (0, 0, 0), (math.pi / 2, 0, -math.pi / 2))
    scene.camera.data.type = "PANO"
    scene.camera.data.panorama_type = "EQUIRECTANGULAR"
    world = scene.world = bpy.data.worlds.new("Pano")
    nodes, links = world.node_tree.nodes, world.node_tree.links
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = save_hdri(bpy, folder / "pano.exr")
    mapping = nodes.new("ShaderNodeMapping")
    links.new(nodes.new("ShaderNodeTexCoord").outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    links.new(env.outputs["Color"], nodes["Background"].inputs["Color"])
    nodes["Background"].inputs["Strength"].default_value = 0.5
    scene.cycles.samples, scene.cycles.device, scene.cycles.use_denoising = 4, "CPU", False
    scene.cycles.use_adaptive_sampling = False
    scene.splat_tracer.samples = 4
    return scene, env, mapping


PANO_CASES = {
    "mirror ball": dict(projection="MIRROR_BALL"),
    "closest": dict(interpolation="Closest"),
    "texture mapping": dict(vector_type="TEXTURE", location=(0.2, 0.0, 0.1), rotation=(0.3, 0.0, 1.0),
                            scale=(1.0, 1.0, 1.5)),
}


@pytest.mark.parametrize("case", list(PANO_CASES))
def test_the_baked_world_is_the_world_cycles_renders(blender, tmp_path, case):
    cfg = PANO_CASES[case]
    scene, env, mapping = _pano_scene(blender, tmp_path)
    env.projection = cfg.get("projection", "EQUIRECTANGULAR")
    env.interpolation = cfg.get("interpolation", "Linear")
    mapping.vector_type = cfg.get("vector_type", "POINT")
    mapping.inputs["Location"].default_value = cfg.get("location", (0, 0, 0))
    mapping.inputs["Rotation"].default_value = cfg.get("rotation", (0, 0, 0))
    mapping.inputs["Scale"].default_value = cfg.get("scale", (1, 1, 1))
    out = {}
    for engine in ("CYCLES", "SPLAT_TRACER"):
        scene.render.engine = engine
        out[engine] = render(blender, scene, tmp_path / f"{engine}.exr", (PANO_W, PANO_H))["ViewLayer"]["Combined"]
    # The sun's few pixels carry most of the difference a half-pixel filter offset makes: the
    # comparison clips at the sky's brightest (a wrong orientation still moves the gradient).
    clip = lambda a: np.minimum(a[..., :3], 1.0)  # noqa: E731
    ours, cycles = clip(out["SPLAT_TRACER"]), clip(out["CYCLES"])
    off = lambda a: float((np.abs(a - cycles).max(-1) > PANO_TOL * cycles.mean()).mean())  # noqa: E731
    print(case, "pixels off", off(ours), "median difference", float(np.median(np.abs(ours - cycles))))
    median = lambda a: float(np.median(np.abs(a - cycles))) / float(cycles.mean())  # noqa: E731
    assert off(ours) < PANO_OFF and median(ours) < PANO_MEDIAN
    # The wrong variant is far off: the other projection, or the mapping ignored.
    if case == "mirror ball":
        env.projection = "EQUIRECTANGULAR"
    else:
        mapping.vector_type, mapping.inputs["Location"].default_value = "POINT", (0, 0, 0)
        mapping.inputs["Rotation"].default_value, mapping.inputs["Scale"].default_value = (0, 0, 0.5), (1, 1, 1)
    if case != "closest":
        wrong = clip(render(blender, scene, tmp_path / "wrong.exr", (PANO_W, PANO_H))["ViewLayer"]["Combined"])
        print(case, "wrong variant: pixels off", off(wrong), "median", median(wrong))
        assert off(wrong) > 2 * PANO_OFF and median(wrong) > PANO_MEDIAN


def test_what_the_bake_approximates_is_said_once(blender, tmp_path):
    """Cubic interpolation (baked as Linear) and a node the bake does not evaluate (a Math
    node on the Strength: its socket's value) are each one report line, naming the node;
    a cached bake says them again in the next frame's report."""
    from blender_helpers import extension_module

    bpy = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    world = scene.world = bpy.data.worlds.new("Said")
    nodes, links = world.node_tree.nodes, world.node_tree.links
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image, env.interpolation = save_hdri(bpy, tmp_path / "said.exr"), "Cubic"
    links.new(env.outputs["Color"], nodes["Background"].inputs["Color"])
    math_node = nodes.new("ShaderNodeMath")
    links.new(math_node.outputs[0], nodes["Background"].inputs["Strength"])
    es = extension_module("blender.export.shading")
    Report = extension_module("render.shading").Report
    for _ in range(2):  # baked, then from the cache
        report = Report()
        w = es.world_of(scene, report)
        assert w.environment is not None
        assert np.allclose(w.environment, hdri()[..., :3], rtol=1e-5)  # Strength: its value 1
        assert len(report.lines) == 2, report.lines
        assert "'Environment Texture' uses Cubic interpolation; baked with Linear" in report.lines[1] + report.lines[0]
        assert any("'Math' node ('Math'), which the world bake does not evaluate; using the default value 1"
                   in line for line in report.lines), report.lines


def test_a_bake_that_fails_renders_the_viewport_colour_and_says_so(blender, tmp_path, monkeypatch):
    from blender_helpers import extension_module

    bpy = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    world = scene.world = bpy.data.worlds.new("Broken")
    world.color = (0.2, 0.3, 0.4)
    nodes = world.node_tree.nodes
    env = nodes.new("ShaderNodeTexEnvironment")
    world.node_tree.links.new(env.outputs["Color"], nodes["Background"].inputs["Color"])
    world_module = extension_module("blender.export.world")

    def broken(*args):
        raise ValueError("no")
    monkeypatch.setattr(world_module, "_bake", broken)
    world_module._cache.clear()
    report = extension_module("render.shading").Report()
    w = extension_module("blender.export.shading").world_of(scene, report)
    assert w.environment is None and w.radiance() == pytest.approx((0.2, 0.3, 0.4))
    assert report.lines == ["world 'Broken': its node tree could not be baked (ValueError: no); "
                            "using the world's viewport colour"]


# --------------------------------------------------------------------------------------
# The Sky Texture's model against Cycles' own: the world alone seen by the panoramic camera,
# by bands of elevation, the sun's neighbourhood left out (a disc of 0.27 degrees in pixels of
# 1.4 is noise at 4 samples; its light is measured on the floor above).

SKY_PANO_CASES = {
    "multiple 30": dict(),
    "multiple 5": dict(sun_elevation=5.0),
    "multiple 60": dict(sun_elevation=60.0),
    "single 30": dict(sky_type="SINGLE_SCATTERING"),
    "altitude 20 km": dict(altitude=20000.0),
    "air 3": dict(air_density=3.0),
    "aerosol 5": dict(aerosol_density=5.0),
    "ozone 0": dict(ozone_density=0.0),
    "preetham": LEGACY_SKIES["sky preetham"],
    "hosek-wilkie": LEGACY_SKIES["sky hosek-wilkie"],
}
SKY_BANDS = {"zenith": slice(0, 20), "upper sky": slice(20, 50), "horizon": slice(58, 64), "ground": slice(70, 128)}
# Band means within SKY_PANO_RTOL of Cycles' (relative; 1e-3 absolute for a black ground).
# Measured: within 0.2 % in every band and case (Cycles' table and ours are the same model),
# the worst the horizon at 5 degrees; Preetham and Hosek-Wilkie (analytic) within 0.05 %, where
# the Multiple Scattering sky that stood in for them before (the default case's, whose bands
# they are compared with) is 2 to 10 times off. Each changed setting moves some band by more than
# SKY_PANO_MOVED (measured: ozone 0 the least, +9.7 %), so ignoring it fails.
SKY_PANO_RTOL, SKY_PANO_MOVED = 0.01, 0.05


@pytest.fixture(scope="module")
def sky_panos(blender, tmp_path_factory):
    folder = tmp_path_factory.mktemp("sky")
    cache = {}

    def get(case):
        if case in cache:
            return cache[case]
        cfg = dict(SKY_PANO_CASES[case])
        scene, _, _ = _pano_scene(blender, folder)
        nodes, links = scene.world.node_tree.nodes, scene.world.node_tree.links
        sky = nodes.new("ShaderNodeTexSky")
        elevation = math.radians(cfg.pop("sun_elevation", 30.0))
        sky.sun_elevation, sky.sun_rotation = elevation, math.radians(120)
        for k, v in cfg.items():
            setattr(sky, k, v)
        links.new(sky.outputs["Color"], nodes["Background"].inputs["Color"])
        nodes["Background"].inputs["Strength"].default_value = 1.0
        out = {}
        for engine in ("CYCLES", "SPLAT_TRACER"):
            scene.render.engine = engine
            out[engine] = render(blender, scene, folder / f"{case}_{engine}.exr",
                                 (PANO_W, PANO_H))["ViewLayer"]["Combined"][..., :3]
        # The pixels' directions (the camera looks along +x, the image's centre), and those
        # within 5 degrees of the sun left out.
        u = (np.arange(PANO_W) + 0.5) / PANO_W
        v = (np.arange(PANO_H) + 0.5) / PANO_H
        phi, el = np.meshgrid((0.5 - u) * 2 * np.pi, (0.5 - v) * np.pi)
        d = np.stack([np.cos(el) * np.cos(phi), np.cos(el) * np.sin(phi), np.sin(el)], -1)
        rot = math.radians(120)
        sun = np.array([math.sin(rot) * math.cos(elevation), math.cos(rot) * math.cos(elevation), math.sin(elevation)])
        keep = d @ sun < math.cos(math.radians(5))
        means = {engine: {k: img[r][keep[r]].mean(0) for k, r in SKY_BANDS.items()} for engine, img in out.items()}
        cache[case] = means
        return means
    return get


@pytest.mark.parametrize("case", list(SKY_PANO_CASES))
def test_the_baked_sky_is_the_sky_cycles_renders(sky_panos, case):
    means = sky_panos(case)
    ours, cycles = means["SPLAT_TRACER"], means["CYCLES"]
    print(case, {k: (ours[k].round(4).tolist(), cycles[k].round(4).tolist()) for k in SKY_BANDS})
    for k in SKY_BANDS:
        assert np.all(np.abs(ours[k] - cycles[k]) <= SKY_PANO_RTOL * cycles[k] + 1e-3), (k, ours[k], cycles[k])
    if case not in ("multiple 30", "multiple 5", "multiple 60"):
        # The setting changes Cycles' sky, and ours the same way: the default's is outside the
        # tolerance (what the fitted model of before did: the default atmosphere always).
        default = sky_panos("multiple 30")["CYCLES"]
        moved = max(float(np.max(np.abs(cycles[k] - default[k]) / np.maximum(default[k], 1e-3))) for k in SKY_BANDS)
        print(case, "moved", moved)
        assert moved > SKY_PANO_MOVED
        for k in SKY_BANDS:
            assert np.all(np.sign(ours[k] - default[k]) == np.sign(cycles[k] - default[k])) or \
                np.all(np.abs(cycles[k] - default[k]) <= SKY_PANO_RTOL * default[k] + 1e-3), k
