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
from test_scene_export import INDEX, cloud_sphere, erode, iou, plane, principled, render

W, H = 160, 120
SAMPLES = 64
FLOOR, SCAN = 1, 2
REGION_RTOL, SHADOW_RTOL, SHADOW_IOU, MOVED_IOU = 0.08, 0.15, 0.6, 0.3
SKY_LIT_RTOL, SKY_SHADOW_RTOL, SKY_GROUND_RTOL = 0.05, 0.5, 1.5  # see the Sky Texture's test
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
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    grey = principled(bpy, "Grey")
    floor = plane(bpy, "Floor", 8.0, (0, 0, 0), grey)
    scan = cloud_sphere(bpy, "Scan", 4000, 0.6, (0, 0, 1.0), grey)
    floor.pass_index, scan.pass_index = FLOOR, SCAN
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
                       plain=env.image)


CASES = {"plain": {}, "mirrored": dict(mirrored=True), "rotated": dict(rotation=90.0),
         "camera_ray": dict(camera_ray=True), "sky": dict(sky=True)}


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
        source = n["mix"] if cfg.get("camera_ray") else n["background"]
        links.new(source.outputs[0], n["output"].inputs["Surface"])
        links.new(n["sky" if cfg.get("sky") else "env"].outputs["Color"], n["background"].inputs["Color"])

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


def test_the_sky_texture_lights_the_floor_and_casts_the_sun_shadow_as_in_cycles(renders):
    """The Sky Texture (Nishita, Multiple Scattering) as a measured model: a uniform dome,
    a uniform ground and the sun disc through the atmosphere (blender/export/world.py).
    Measured with the sun at 30 degrees, turned 120 (the model was measured at 15, 40 and 70):
    lit floor (21.09, 18.75, 16.22) here, (21.49, 19.17, 16.66) in Cycles (-2 to -3 %); the
    shadow's outline overlaps 86 %; in the shadow (2.46, 3.47, 5.36) against (1.84, 2.97, 5.02):
    +7 to +34 %, the dome being uniform (Cycles' is brightest near the sun, which the ball
    hides); the ground below the horizon (0.23, 0.27, 0.36) against (0.10, 0.16, 0.28), up to
    2.3x: a uniform ground where Cycles' darkens away from the sun. The tolerances say so:
    SKY_LIT_RTOL 0.05, SKY_SHADOW_RTOL 0.5, SKY_GROUND_RTOL 1.5 (relative)."""
    cycles, ours = renders("sky", "CYCLES"), renders("sky")
    lit, shadow = floor_masks(cycles)
    masks = {"lit floor": lit, "shadow": shadow, "ground": erode(cycles[INDEX] == 0, 2)}
    assert all(m.sum() > 100 for m in masks.values()), {k: int(m.sum()) for k, m in masks.items()}
    mc, mo = region_means(cycles, masks), region_means(ours, masks)
    print({k: (mo[k].round(3).tolist(), mc[k].round(3).tolist()) for k in masks})
    _, ours_shadow = floor_masks(ours, cycles)
    print("sky shadow IoU", iou(ours_shadow, shadow))
    assert close(mo["lit floor"], mc["lit floor"], SKY_LIT_RTOL)
    assert close(mo["shadow"], mc["shadow"], SKY_SHADOW_RTOL)
    assert close(mo["ground"], mc["ground"], SKY_GROUND_RTOL)
    assert iou(ours_shadow, shadow) > SHADOW_IOU
    # What the engine did before (the default sky's dome alone, no sun: 0.8 x (1.7, 2.9, 4.8)
    # on this floor) is 10x too dark.
    assert not close(0.8 * np.array([1.7, 2.9, 4.8]), mc["lit floor"], 5 * SKY_LIT_RTOL)


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
