"""Noise control side by side with Cycles (issue 25, item 4), through real Blender.

Each test renders one scene with both engines, with the noise setting (read from
scene.cycles) off and on, and compares what the setting does. Images 64x48, meshes only
(so that Cycles sees what we see), tolerances stated per test with the values measured
(bpy 5.0.1) and why a wrong render fails them.

Fireflies are counted as pixels brighter than 10x the median of their 5x5 neighbourhood
(plus 0.05, so that a black neighbourhood's dim pixels are not counted).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import median_filter

from test_scene_export import black_world, lamp, mesh_object, plane, principled, render, stats, uv_sphere
from blender_helpers import add_camera

W, H = 64, 48
ENGINES = ("SPLAT_TRACER", "CYCLES")


def _cycles_common(scene, samples):
    c = scene.cycles
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling = samples, "CPU", False, False
    c.sample_clamp_direct = c.sample_clamp_indirect = c.blur_glossy = 0.0
    c.seed = 0
    scene.view_settings.view_transform = "Standard"


def _render(bpy, scene, tmp_path, engine, name, size=(W, H)):
    scene.render.engine = engine
    out = render(bpy, scene, tmp_path / f"{name}_{engine}.exr", size)["ViewLayer"]
    return out


def lum(rgb):
    return rgb[..., :3].mean(axis=-1)


def outliers(img) -> int:
    l = lum(img)
    return int((l > 10 * median_filter(l, size=5) + 0.05).sum())


def rect(bpy, name, xs, ys, material):
    """A rectangle [xs] x [ys] on the ground, facing up."""
    def build(bm):
        bm.faces.new([bm.verts.new((x, y, 0.0)) for x, y in ((xs[0], ys[0]), (xs[1], ys[0]), (xs[1], ys[1]), (xs[0], ys[1]))])
    return mesh_object(bpy, name, build, materials=[material])


def firefly_scene(bpy, scene):
    """A matte floor seen from above under a dim sun (0.076, noise-free), and a bright spot
    lamp making a hot patch on a matte wall the camera does not see: the floor's bounce
    light from the patch is found by few of its diffuse rays (fireflies)."""
    matte = principled(bpy, "Matte")
    plane(bpy, "Floor", 4.0, (0, 0, 0), matte)
    # The wall x = 2.5 (facing -x), outside the view.

    def wall(bm):
        vs = [bm.verts.new(v) for v in ((2.5, -3, 0), (2.5, -3, 3), (2.5, 3, 3), (2.5, 3, 0))]
        bm.faces.new(vs)
    mesh_object(bpy, "Wall", wall, materials=[matte])
    lamp(bpy, "SPOT", location=(0.0, 0.0, 1.5), rotation=(0, math.radians(-90), 0), energy=4000.0,
         spot_size=math.radians(30), spot_blend=0.0, shadow_soft_size=0.0)
    lamp(bpy, "SUN", energy=0.3, angle=0.0)
    add_camera(bpy, scene, (0, 0, 4.0), (0, 0, 0), lens=35.0)
    black_world(bpy, scene)
    _cycles_common(scene, 16)


def highlight_scene(bpy, scene):
    shiny = principled(bpy, "Shiny", base=(0.8, 0.8, 0.8), roughness=0.2, metallic=1.0)
    plane(bpy, "Floor", 4.0, (0, 0, 0), shiny)
    lamp(bpy, "POINT", location=(0, 1.0, 2.0), energy=100.0, shadow_soft_size=0.05)
    add_camera(bpy, scene, (0, -1.0, 2.0), (math.radians(45), 0, 0), lens=35.0)
    black_world(bpy, scene)
    _cycles_common(scene, 16)



def adaptive_scene(bpy, scene):
    """Left: an emitting plane (flat: no light falls on it); right: the firefly scene's floor."""
    firefly_scene(bpy, scene)
    bpy.data.objects.remove(bpy.data.objects["Floor"])
    rect(bpy, "Floor", (0, 3), (-3, 3), principled(bpy, "Matte2"))
    rect(bpy, "Glow", (-3, 0), (-3, 3), principled(bpy, "Glow", base=(0, 0, 0), specular=0.0, emission=(1, 1, 1, 0.3)))
    scene.view_layers[0].cycles.pass_debug_sample_count = True



def caustic_scene(bpy, scene):
    """A mirror ball over a matte floor, a small spot above it whose cone (14 degrees, the
    ball's 15.3) lights the ball only: the floor's light comes through the ball (a caustic
    path: diffuse, then mirror, then the lamp)."""
    rect(bpy, "Floor", (-3, 3), (-3, 3), principled(bpy, "Matte"))
    ball = uv_sphere(bpy, "Ball", 0.5, (0, 0, 0.6), principled(bpy, "Chrome", base=(0.9, 0.9, 0.9), roughness=0.0, metallic=1.0))
    ball.pass_index = 1
    lamp(bpy, "SPOT", location=(0, 0, 2.5), energy=30000.0, shadow_soft_size=0.05,
         spot_size=math.radians(28), spot_blend=0.0)
    add_camera(bpy, scene, (0, 0, 5.0), (0, 0, 0), lens=35.0)
    black_world(bpy, scene)
    _cycles_common(scene, 32)
    scene.view_layers[0].use_pass_object_index = True



def _index(out):
    index = out["Object Index"]
    return index if index.ndim == 2 else index[..., 0]


# --------------------------------------------------------------------------------------
# Clamping.

CLAMP_RTOL = 0.05


def test_clamp_indirect_removes_the_fireflies_as_cycles_does(blender, empty_scene, tmp_path):
    """The floor's bounce light comes from a hot patch on the wall: at 16 samples, fireflies.
    Clamp Indirect 1 removes them in both engines. Measured: unclamped max 1.90 / 1.93
    (ours / Cycles), 20 / 23 fireflies (124 with independent random numbers: both engines'
    samples are stratified now); clamped max 0.27 / 0.28, none; clamped mean 0.1000 / 0.0989 (1.1 %),
    the sun alone gives 0.076. CLAMP_RTOL = 5 % on the mean: the unclamped mean (0.29) fails
    it, and so does a clamp 3x too strong (0.3: mean 0.0823, -17 %)."""
    bpy, scene = blender, empty_scene
    firefly_scene(bpy, scene)
    out = {}
    for clamp in (0.0, 1.0):
        scene.cycles.sample_clamp_indirect = clamp
        out.update({(e, clamp): _render(bpy, scene, tmp_path, e, f"indirect{clamp}")["Combined"] for e in ENGINES})
    for (e, clamp), img in out.items():
        print(f"clamp indirect {clamp} {e}: mean {lum(img).mean():.4f} max {lum(img).max():.3f} "
              f"fireflies {outliers(img)}")
    for e in ENGINES:
        free, clamped = out[e, 0.0], out[e, 1.0]
        assert outliers(free) >= 10 and outliers(clamped) == 0, e
        assert lum(clamped).max() < lum(free).max() / 3, e
    reference = lum(out["CYCLES", 1.0]).mean()
    assert lum(out["SPLAT_TRACER", 1.0]).mean() == pytest.approx(reference, rel=CLAMP_RTOL)
    assert lum(out["SPLAT_TRACER", 0.0]).mean() != pytest.approx(reference, rel=CLAMP_RTOL)  # not vacuous


def test_clamp_direct_caps_a_highlight_as_cycles_does(blender, empty_scene, tmp_path):
    """A small bright lamp's highlight on rough metal, seen directly (peak 55 in both).
    Clamp Direct 0.5 caps a sample's R + G + B at 1.5. Measured: clamped mean 0.0448 /
    0.0452 (ours / Cycles, 1 %), max 0.500 / 0.594 (Cycles clamps its lamp sample and its
    BSDF sample's hit of the lamp each on its own; ours samples the lamp only); unclamped
    mean 0.40, far outside CLAMP_RTOL."""
    bpy, scene = blender, empty_scene
    highlight_scene(bpy, scene)
    out = {}
    for clamp in (0.0, 0.5):
        scene.cycles.sample_clamp_direct = clamp
        out.update({(e, clamp): lum(_render(bpy, scene, tmp_path, e, f"direct{clamp}")["Combined"]) for e in ENGINES})
    for (e, clamp), l in out.items():
        print(f"clamp direct {clamp} {e}: mean {l.mean():.4f} max {l.max():.3f}")
    for e in ENGINES:
        assert out[e, 0.0].max() > 20 and out[e, 0.5].max() < 0.5 * 1.25, e
    assert out["SPLAT_TRACER", 0.5].max() <= 0.5 * (1 + 1e-4)
    reference = out["CYCLES", 0.5].mean()
    assert out["SPLAT_TRACER", 0.5].mean() == pytest.approx(reference, rel=CLAMP_RTOL)
    assert out["SPLAT_TRACER", 0.0].mean() != pytest.approx(reference, rel=CLAMP_RTOL)


# --------------------------------------------------------------------------------------
# Adaptive sampling.

N, THRESHOLD = 128, 0.05
ERROR_FACTOR = 1.15  # adaptive's RMSE against the reference at most this times the fixed one's


def _our_mean_samples(bpy, scene, tmp_path, x0, x1):
    """The engine's mean samples a pixel took in the border [x0, x1] of the width (the
    engine writes no per-pixel sample count; its counters count the window's)."""
    r = scene.render
    r.use_border, r.use_crop_to_border = True, False
    r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = x0, x1, 0.0, 1.0
    try:
        _render(bpy, scene, tmp_path, "SPLAT_TRACER", f"border{x0}")
    finally:
        r.use_border = False
    return stats()["samples_taken"] / (round((x1 - x0) * W) * H)


def test_adaptive_sampling_reaches_the_same_error_with_fewer_samples_as_cycles(blender, empty_scene, tmp_path):
    """Left half: an emitting plane (flat); right half: the firefly scene's floor (noisy).
    Noise Threshold 0.05 (Min Samples automatic: 40), 128 samples, against each engine's own
    512-sample reference. Measured RMSE fixed / adaptive: ours 0.0530 / 0.0530, Cycles
    0.0585 / 0.0585 (ours 0.0975 with independent random numbers); mean samples ours 89.7 of
    128 (70 %), Cycles 0.70 of the samples (its Debug Sample Count pass: a fraction); flat half
    ours 50, Cycles 0.40 x 128 = 51, noisy half 128 in both. The flat half costing no more
    than half the samples and the noisy one nearly all is what fails an engine that stops
    pixels on anything but their noise."""
    bpy, scene = blender, empty_scene
    adaptive_scene(bpy, scene)
    c = scene.cycles
    c.samples = 512
    reference = {e: lum(_render(bpy, scene, tmp_path, e, "reference")["Combined"]) for e in ENGINES}
    c.samples, c.adaptive_threshold, c.adaptive_min_samples = N, THRESHOLD, 0
    error, counts = {}, {}
    for adaptive in (False, True):
        c.use_adaptive_sampling = adaptive
        for e in ENGINES:
            out = _render(bpy, scene, tmp_path, e, f"adaptive{adaptive}")
            error[e, adaptive] = float(np.sqrt(np.mean((lum(out["Combined"]) - reference[e]) ** 2)))
            if adaptive and e == "CYCLES":
                count = out["Debug Sample Count"]
                count = (count if count.ndim == 2 else count[..., 0]) * N
                counts[e] = (count.mean(), count[:, : W // 2].mean(), count[:, W // 2:].mean())
            elif adaptive:
                counts[e] = (stats()["samples_taken"] / (W * H),
                             _our_mean_samples(bpy, scene, tmp_path, 0.0, 0.5),
                             _our_mean_samples(bpy, scene, tmp_path, 0.5, 1.0))
    print("RMSE (engine, adaptive):", error)
    print("mean samples (all, flat half, noisy half):", counts)
    for e in ENGINES:
        assert error[e, True] <= ERROR_FACTOR * error[e, False], e
        everything, flat, noisy = counts[e]
        assert everything < 0.8 * N, e
        assert flat < 0.5 * N and noisy > 0.95 * N, e
    ours, cycles = counts["SPLAT_TRACER"], counts["CYCLES"]
    assert ours[0] == pytest.approx(cycles[0], rel=0.1)  # the samples saved: within 10 % of Cycles'


# --------------------------------------------------------------------------------------
# Filter Glossy.

GLOSSY_RTOL = 0.25


def _floor_mean(out):
    return float(lum(out["Combined"])[_index(out) < 0.5].mean())


def test_filter_glossy_lights_the_floor_as_cycles_does(blender, empty_scene, tmp_path):
    """A spot lights only a mirror ball; the floor gets its light through the ball (a
    caustic: diffuse, mirror, lamp). Filter Glossy 1 blurs the mirror after the floor's
    bounce, so its lamp can be sampled. Measured floor mean with Filter Glossy 1, 64 samples:
    ours 0.148, Cycles 0.169 (-13 %; 512 samples: 0.153 and 0.161, -4.5 %): GLOSSY_RTOL = 25 %
    for 64 samples' noise. Filter Glossy 0 (0.005 at 64 samples in both) fails it. Cycles'
    floor is noisier with Filter Glossy 0: relative RMSE against its own 512-sample render
    37 against 5.8 (the caustic is found only by a mirror ray hitting the lamp)."""
    bpy, scene = blender, empty_scene
    caustic_scene(bpy, scene)
    c = scene.cycles
    c.samples = 64
    floor = {}
    for blur in (0.0, 1.0):
        c.blur_glossy = blur
        floor.update({(e, blur): _render(bpy, scene, tmp_path, e, f"glossy{blur}") for e in ENGINES})
    means = {k: _floor_mean(v) for k, v in floor.items()}
    print("floor means (engine, filter glossy):", means)
    assert means["SPLAT_TRACER", 1.0] == pytest.approx(means["CYCLES", 1.0], rel=GLOSSY_RTOL)
    assert means["SPLAT_TRACER", 0.0] != pytest.approx(means["CYCLES", 1.0], rel=GLOSSY_RTOL)
    c.samples = 512
    relative_error = {}
    for blur in (0.0, 1.0):
        c.blur_glossy = blur
        ref = _render(bpy, scene, tmp_path, "CYCLES", f"glossy_reference{blur}")
        on_floor = _index(ref) < 0.5
        diff = lum(floor["CYCLES", blur]["Combined"]) - lum(ref["Combined"])
        relative_error[blur] = float(np.sqrt(np.mean(diff[on_floor] ** 2)) / lum(ref["Combined"])[on_floor].mean())
    print("Cycles' relative RMSE by filter glossy:", relative_error)
    assert relative_error[0.0] > 3 * relative_error[1.0]

