"""An emissive mesh panel as the only light, beside Cycles (real bpy; issue 25, item 4): a
floor and a scan (a splat cloud; its mesh twin for Cycles, which renders a cloud as balls)
lit by an emissive plane, nothing else. Before mesh lights, the panel was found only by the
diffuse rays that happened to hit it: most of the floor was black where Cycles' was lit.
The same panel under Clamp Direct, and over a shadow-catcher floor, against Cycles too."""
from __future__ import annotations

import math

import numpy as np

from blender_helpers import add_camera, extension_module, read_exr, render_to_exr
from geometry import fibonacci_sphere

W, H = 96, 72
SAMPLES = 4
# The issue's requirement: the share of black floor pixels within 2x of Cycles' at the same
# samples. "Black": below 2 % of Cycles' median floor luminance (a pixel none of whose
# samples found light); the share is floored at 1 % on both sides, as both are about 1 %
# here (the sphere's umbra) and a ratio of two near-zero shares is noise.
BLACK_FRACTION, BLACK_RATIO, BLACK_FLOOR = 0.02, 2.0, 0.01
# Mean floor luminance relative to Cycles' (measured 0.9 % apart at 4 samples, 0.07 % at 64
# samples and twice the size; the lamp tests' 3 % plus 1 % for two 4-sample images).
BRIGHTNESS_TOLERANCE = 0.04
STRENGTH = 12.0  # the panel's Emission Strength
CLAMP_SAMPLES, CLAMP_DIRECT, CLAMP_RTOL = 16, 0.1, 0.05
# The catcher test's world: some light on the catcher-only path, whose black would make the
# pass 1 by its rule (a ratio over nothing).
WORLD, CATCHER_RTOL = 0.1, 0.05


def build(bpy):
    from splat_tracer.blender import cloud_object

    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    grey = bpy.data.materials.new("Grey")
    bsdf = grey.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1)
    bsdf.inputs["Roughness"].default_value = 1.0
    bsdf.inputs["Specular IOR Level"].default_value = 0.0

    bpy.ops.mesh.primitive_plane_add(size=8.0)
    floor = bpy.context.object
    floor.data.materials.append(grey)

    # The scan: a sphere of splats resting on the floor, and its mesh twin for Cycles.
    centre, radius = (0.3, 0.2, 0.5), 0.5
    p, n = fibonacci_sphere(6000, radius)
    cloud = cloud_object.create_cloud_object("Scan", p, n, np.full(len(p), 0.025), None, location=centre)
    cloud.data.materials.append(grey)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, location=centre, segments=64, ring_count=32)
    twin = bpy.context.object
    bpy.ops.object.shade_smooth()
    twin.data.materials.append(grey)

    # The light: a 0.8 m emissive square 2 m up, tilted towards the camera, facing down.
    glow = bpy.data.materials.new("Glow")
    nodes = glow.node_tree.nodes
    nodes.remove(nodes["Principled BSDF"])
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = STRENGTH
    glow.node_tree.links.new(emission.outputs[0], nodes["Material Output"].inputs["Surface"])
    bpy.ops.mesh.primitive_plane_add(size=0.8, location=(-0.6, 0.4, 2.0), rotation=(math.radians(160), 0, 0))
    panel = bpy.context.object
    panel.data.materials.append(glow)

    add_camera(bpy, scene, (0.0, -6.0, 3.0), (math.radians(63), 0, 0), lens=35)
    scene.world = bpy.data.worlds.new("Black")
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    c = scene.cycles
    # Direct light and one diffuse bounce in both engines (the engine reads Cycles' bounces).
    c.max_bounces, c.diffuse_bounces = 2, 1
    c.glossy_bounces = c.transmission_bounces = c.transparent_max_bounces = 0
    c.device, c.samples, c.use_denoising, c.use_adaptive_sampling = "CPU", SAMPLES, False, False
    scene.view_settings.view_transform = "Standard"
    scene.splat_tracer.samples = SAMPLES
    return scene, cloud, twin, glow


def luminance(rgb):
    return rgb[..., :3] @ np.array([0.2126, 0.7152, 0.0722])


def floor_pixels(image):
    return (image["depth"] < 1e9) & (image["normal"][..., 2] > 0.99)


def measure(ours, cycles):
    """(black share ours, black share Cycles, mean ratio) over the floor both renders see."""
    floor = floor_pixels(ours) & floor_pixels(cycles)
    lo, lc = luminance(ours["rgba"])[floor], luminance(cycles["rgba"])[floor]
    dark = BLACK_FRACTION * np.median(lc)
    return float((lo < dark).mean()), float((lc < dark).mean()), float(lo.mean() / lc.mean()), int(floor.sum())


def within(black, cycles_black, ratio):
    shares = max(black, BLACK_FLOOR) / max(cycles_black, BLACK_FLOOR)
    return 1 / BLACK_RATIO <= shares <= BLACK_RATIO and abs(ratio - 1) < BRIGHTNESS_TOLERANCE


def test_an_emissive_panel_lights_a_floor_and_a_scan_as_in_cycles(blender, tmp_path):
    """Measured at 4 samples: black floor pixels 1.7 % here, 1.5 % in Cycles; the floor's mean
    luminance 0.9 % below Cycles'. The panel's Emission Sampling set to None (the panel found
    by diffuse rays only: the engine before mesh lights) leaves 97 % of the floor black, which
    the test rejects."""
    bpy = blender
    scene, cloud, twin, glow = build(bpy)
    twin.hide_render = True
    scene.render.engine = "SPLAT_TRACER"
    ours = render_to_exr(bpy, scene, tmp_path / "ours.exr", W, H)
    glow.cycles.emission_sampling = "NONE"
    unsampled = render_to_exr(bpy, scene, tmp_path / "unsampled.exr", W, H)
    glow.cycles.emission_sampling = "AUTO"
    twin.hide_render, cloud.hide_render = False, True
    scene.render.engine = "CYCLES"
    cycles = render_to_exr(bpy, scene, tmp_path / "cycles.exr", W, H)

    black, cycles_black, ratio, pixels = measure(ours, cycles)
    print(f"black: ours {black:.4f}, Cycles {cycles_black:.4f}; mean ours / Cycles {ratio:.4f} over {pixels} px")
    assert pixels > 2500
    assert within(black, cycles_black, ratio), (black, cycles_black, ratio)
    old_black, _, old_ratio, _ = measure(unsampled, cycles)
    print(f"unsampled: black {old_black:.4f}, mean ratio {old_ratio:.4f}")
    assert not within(old_black, cycles_black, old_ratio)
    assert old_black > 0.5


def test_an_emissive_cloud_is_said_not_to_be_sampled(blender, tmp_path):
    """A cloud whose material emits (as Cycles would sample it: Emission Sampling Auto over
    its threshold) lights the scene only through the rays that meet it: the report says so
    in one line. With Emission Sampling None there is nothing to say."""
    bpy = blender
    scene, cloud, twin, glow = build(bpy)
    twin.hide_render = True
    scene.render.engine = "SPLAT_TRACER"
    cloud.data.materials[0] = glow
    render_to_exr(bpy, scene, tmp_path / "glowing.exr", 16, 12, passes=False)
    report = extension_module("blender.session").HISTORY[-1]["report"]
    lines = [line for line in report if "not sampled as a light" in line]
    assert len(lines) == 1 and "'Scan'" in lines[0], report
    glow.cycles.emission_sampling = "NONE"
    render_to_exr(bpy, scene, tmp_path / "none.exr", 16, 12, passes=False)
    assert not [line for line in extension_module("blender.session").HISTORY[-1]["report"] if "sampled" in line]


def test_clamp_direct_caps_the_panels_light_as_in_cycles(blender, tmp_path):
    """Clamp Direct with a mesh light: each light sample (one of Cycles' shadow rays) and
    each emission a first bounce meets, after its MIS weight, is capped at R + G + B = 3 x
    the clamp. Floor pixels, 16 samples, Clamp Indirect off. Measured (bpy 5.0.1): clamped
    mean 0.0608 here, 0.0609 in Cycles; unclamped 0.0868 and 0.0869. CLAMP_RTOL = 5 %: the
    unclamped image (what the engine would do ignoring the clamp for mesh lights) is 43 %
    off."""
    bpy = blender
    scene, cloud, twin, glow = build(bpy)
    c = scene.cycles
    c.samples, c.sample_clamp_indirect, c.blur_glossy = CLAMP_SAMPLES, 0.0, 0.0
    means = {}
    for engine, hidden in (("SPLAT_TRACER", twin), ("CYCLES", cloud)):
        twin.hide_render = cloud.hide_render = False
        hidden.hide_render = True
        scene.render.engine = engine
        for clamp in (0.0, CLAMP_DIRECT):
            c.sample_clamp_direct = clamp
            image = render_to_exr(bpy, scene, tmp_path / f"{engine}_{clamp}.exr", W, H)
            means[engine, clamp] = image
    floor = floor_pixels(means["SPLAT_TRACER", 0.0]) & floor_pixels(means["CYCLES", 0.0])
    m = {key: float(luminance(image["rgba"])[floor].mean()) for key, image in means.items()}
    print({f"{e} {clamp}": round(v, 4) for (e, clamp), v in m.items()})
    ours, cycles = m["SPLAT_TRACER", CLAMP_DIRECT], m["CYCLES", CLAMP_DIRECT]
    assert abs(ours / cycles - 1) < CLAMP_RTOL, (ours, cycles)
    # The clamp takes a real share of the light in both engines: unclamped fails the check.
    for engine in ("SPLAT_TRACER", "CYCLES"):
        assert m[engine, CLAMP_DIRECT] < (1 - 3 * CLAMP_RTOL) * m[engine, 0.0], engine
    assert abs(m["SPLAT_TRACER", 0.0] / cycles - 1) > 3 * CLAMP_RTOL


def test_a_catcher_floor_catches_the_panels_light_as_in_cycles(blender, tmp_path):
    """The floor a shadow catcher, the panel an ordinary object: Cycles leaves the panel's
    emission out of the catcher-only path (its light sampling and its rays alike), so the
    Shadow Catcher pass is the floor's light with the panel over its light without it --
    above 1 where the panel lights it. Measured over the floor (world 0.1): 2.044 here, 2.059
    in Cycles; with the panel kept in the catcher-only path's light sampling, 0.974 here,
    which CATCHER_RTOL = 5 % rejects."""
    bpy = blender
    scene, cloud, twin, glow = build(bpy)
    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (WORLD,) * 3 + (1,)
    floor = bpy.data.objects["Plane"]
    floor.is_shadow_catcher = True
    scene.render.film_transparent = True
    scene.view_layers[0].cycles.use_pass_shadow_catcher = True
    passes = {}
    for engine, hidden in (("SPLAT_TRACER", twin), ("CYCLES", cloud)):
        twin.hide_render = cloud.hide_render = False
        hidden.hide_render = True
        scene.render.engine = engine
        passes[engine, "image"] = render_to_exr(bpy, scene, tmp_path / f"catcher_{engine}.exr", W, H)
        channels = read_exr(tmp_path / f"catcher_{engine}.exr")
        passes[engine] = np.stack([channels[f"ViewLayer.Shadow Catcher.{c}"].pixels for c in "RGB"], -1).mean(-1)
    region = floor_pixels(passes["SPLAT_TRACER", "image"]) & floor_pixels(passes["CYCLES", "image"])
    ours, cycles = float(passes["SPLAT_TRACER"][region].mean()), float(passes["CYCLES"][region].mean())
    print(f"Shadow Catcher pass over the floor: ours {ours:.4f}, Cycles {cycles:.4f}")
    assert cycles > 1.5  # Cycles' rule, as read from its kernel
    assert abs(ours / cycles - 1) < CATCHER_RTOL, (ours, cycles)
