"""Denoising (issue 25) beside Cycles: Cycles' Denoise settings applied with OpenImageDenoise as
Blender ships it (blender/denoise.py).

A sphere cloud and a cube on a floor, lit by an area lamp (soft shadows: noise at few
samples), rendered at NOISY_SAMPLES with Denoise off and on, against each engine's own
REFERENCE_SAMPLES render. Denoising must lower our error by at least MIN_GAIN (Cycles' gain
is measured and printed beside it); with Denoise off the image is the engine's own,
bit-identical to the "Noisy Image" pass of the denoised render; the denoising passes carry
Cycles' names, and the Denoising Normal is in camera space as Cycles writes it.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from blender_helpers import add_camera, extension_module
from test_scene_export import black_world, cloud_sphere, cube, plane, principled, render

W, H = 96, 64
NOISY_SAMPLES, REFERENCE_SAMPLES = 4, 256
# Measured (96 x 64): RMS error against the reference 0.0905 -> 0.0336 denoised (2.7x); Cycles
# 0.1286 -> 0.0390 (3.3x). Asked: 1.5x, well above no denoising's 1.0.
MIN_GAIN = 1.5


def _names():
    """The extension's names of the denoising passes (export/settings.py: their one spelling;
    test_denoising_passes_have_cycles_names checks them against Cycles' render)."""
    return extension_module("blender.export.settings")


def _scene(bpy, scene):
    cloud_sphere(bpy, "Ball", 4000, 0.6, (-0.5, 0.0, 0.6), principled(bpy, "B", (0.2, 0.4, 0.8)))
    cube(bpy, "Cube", 0.8, (0.8, 0.3, 0.4), principled(bpy, "Y", (0.8, 0.7, 0.2)))
    plane(bpy, "Floor", 8.0, (0, 0, 0), principled(bpy, "Grey", (0.6, 0.6, 0.6)))
    light = bpy.data.lights.new("Area", "AREA")
    light.energy, light.size = 300.0, 2.0
    lamp = bpy.data.objects.new("Area", light)
    scene.collection.objects.link(lamp)
    lamp.location, lamp.rotation_euler = (1.0, -1.0, 3.0), (math.radians(20), math.radians(10), 0)
    black_world(bpy, scene)
    add_camera(bpy, scene, (0.0, -5.0, 2.5), (math.radians(65), 0, 0))
    c = scene.cycles
    c.use_adaptive_sampling = False
    c.max_bounces = 1
    c.denoising_input_passes, c.denoising_prefilter = "RGB_ALBEDO_NORMAL", "ACCURATE"


def _rgb(out):
    return out["ViewLayer"]["Combined"][..., :3]


def _rms(a, b) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


def _renders(bpy, scene, tmp_path, engine) -> dict:
    scene.render.engine = engine
    c = scene.cycles
    out = {}
    for name, samples, denoise in (("reference", REFERENCE_SAMPLES, False), ("noisy", NOISY_SAMPLES, False),
                                   ("denoised", NOISY_SAMPLES, True)):
        c.samples, c.use_denoising = samples, denoise
        out[name] = render(bpy, scene, tmp_path / f"{engine}_{name}.exr", (W, H))
    return out


def test_denoising_lowers_the_error_as_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    _scene(bpy, scene)
    scene.cycles.device = "CPU"
    errors = {}
    for engine in ("SPLAT_TRACER", "CYCLES"):
        r = _renders(bpy, scene, tmp_path, engine)
        errors[engine] = (_rms(_rgb(r["noisy"]), _rgb(r["reference"])), _rms(_rgb(r["denoised"]), _rgb(r["reference"])))
        if engine == "SPLAT_TRACER":
            ours = r
    (noisy, denoised), (c_noisy, c_denoised) = errors["SPLAT_TRACER"], errors["CYCLES"]
    print(f"RMS error against {REFERENCE_SAMPLES} samples: ours {noisy:.4f} -> {denoised:.4f} "
          f"({noisy / denoised:.2f}x), Cycles {c_noisy:.4f} -> {c_denoised:.4f} ({c_noisy / c_denoised:.2f}x)")
    assert noisy / denoised >= MIN_GAIN, (noisy, denoised)
    # Denoise off: the engine's own image, which the denoised render keeps as Noisy Image.
    names = _names()
    np.testing.assert_array_equal(ours["noisy"]["ViewLayer"]["Combined"],
                                  ours["denoised"]["ViewLayer"][names.NOISY_IMAGE])
    assert names.NOISY_IMAGE not in ours["noisy"]["ViewLayer"]
    stats = extension_module("blender.session").HISTORY
    said = [s["sampling"] for s in stats[-3:]]
    inputs = f"from the image, {names.DENOISING_ALBEDO} and {names.DENOISING_NORMAL}"
    assert sum(f"denoised by OpenImageDenoise (CPU) {inputs}" in s for s in said) == 1, said


def test_denoising_passes_have_cycles_names(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    _scene(bpy, scene)
    scene.cycles.samples, scene.cycles.use_denoising = NOISY_SAMPLES, True
    scene.view_layers[0].cycles.denoising_store_passes = True
    scene.view_layers[0].use_pass_normal = True
    scene.render.engine = "SPLAT_TRACER"
    ours = render(bpy, scene, tmp_path / "ours.exr", (W, H))["ViewLayer"]
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    cycles = render(bpy, scene, tmp_path / "cycles.exr", (W, H))["ViewLayer"]
    names = _names()
    denoising = (names.NOISY_IMAGE, *names.DENOISING_DATA)
    assert len(denoising) == 4
    assert set(denoising) <= set(cycles), sorted(cycles)
    assert set(denoising) <= set(ours), sorted(ours)
    for name in denoising:
        assert ours[name].shape == cycles[name].shape, name
    # Camera-space normals, as Cycles': where both see the floor, the same vector.
    albedo, normal = names.DENOISING_ALBEDO, names.DENOISING_NORMAL
    floor = (np.abs(ours[albedo] - 0.6).max(axis=-1) < 0.05) & \
            (np.abs(cycles[albedo] - 0.6).max(axis=-1) < 0.1)
    assert floor.sum() > 200, floor.sum()
    np.testing.assert_allclose(np.median(ours[normal][floor], axis=0),
                               np.median(cycles[normal][floor], axis=0), atol=0.05)
    # The world-space Normal pass is not it (the floor's (0, 0, 1) there): the test sees the space.
    world = np.median(ours["Normal"][floor], axis=0)
    assert np.abs(world - np.median(cycles[normal][floor], axis=0)).max() > 0.3, world


def test_denoise_off_without_passes_is_the_plain_render(blender, empty_scene):
    """With Denoise off and no denoising pass the frame takes the path it took before
    denoising existed: no pass added, nothing reported."""
    bpy, scene = blender, empty_scene
    _scene(bpy, scene)
    scene.cycles.samples, scene.cycles.use_denoising = 1, False
    scene.render.engine = "SPLAT_TRACER"
    bpy.ops.render.render()
    stats = extension_module("blender.session").HISTORY[-1]
    assert stats["denoise_seconds"] == 0.0 and "denoised" not in stats["sampling"], stats


def test_viewport_denoises_its_last_pass(blender, empty_scene):
    """Cycles' viewport Denoise (use_preview_denoising): the viewport's last pass is denoised
    (the F12 image with the viewport's samples, then OIDN); the passes before it are not.
    Off, the last pass is the undenoised one."""
    from test_viewport import _f12_view

    viewport = extension_module("blender.viewport")
    bpy, scene = blender, empty_scene
    _scene(bpy, scene)
    scene.cycles.samples = scene.cycles.preview_samples = NOISY_SAMPLES
    scene.render.engine = "SPLAT_TRACER"
    images = {}
    for on in (False, True):
        scene.cycles.use_preview_denoising = on
        bpy.context.view_layer.update()
        vs = viewport.ViewportSession()
        vs.set_view(_f12_view(bpy, scene, W, H))
        vs.update(bpy.context.evaluated_depsgraph_get())
        passes = []
        while vs.step():
            passes.append(vs.latest())
        passes.append(vs.latest())
        vs.close()
        images[on] = passes
    plain, denoised = images[False][-1], images[True][-1]
    assert denoised.denoised and not plain.denoised and not any(p.denoised for p in images[True][:-1])
    assert "denoised" in viewport.status({"SCENE": denoised}, True)
    # Denoising smooths: the mean absolute difference between neighbouring pixels drops.
    rough = lambda im: float(np.abs(np.diff(im.pixels[..., :3], axis=1)).mean())
    print(f"viewport neighbour difference {rough(plain):.4f} -> {rough(denoised):.4f}")
    assert rough(denoised) < 0.8 * rough(plain)
    np.testing.assert_array_equal(images[True][-2].pixels, images[False][-2].pixels)


def test_a_failing_denoiser_keeps_the_frame_and_says_so(blender, empty_scene, monkeypatch):
    """Skip, don't refuse: OIDN failing (an older Blender's library refusing a setting) leaves
    the frame rendered, noisy, with one report line -- and no claim that it was denoised."""
    bpy, scene = blender, empty_scene
    _scene(bpy, scene)
    scene.cycles.samples, scene.cycles.use_denoising = 1, True
    scene.render.engine = "SPLAT_TRACER"

    def fail(*args, **kwargs):
        raise RuntimeError("OpenImageDenoise: invalid argument")

    monkeypatch.setattr(extension_module("blender.denoise"), "denoise", fail)
    bpy.ops.render.render()
    stats = extension_module("blender.session").HISTORY[-1]
    assert stats["completed"]
    assert stats["report"].count("Denoise failed (OpenImageDenoise: invalid argument): the image is not denoised") == 1
    assert "denoised" not in stats["sampling"], stats["sampling"]


CLEAN_PROCESS_RENDER = """
from tools import dev_extension
home = dev_extension.isolate_user_dirs()
import bpy, math
dev_extension.enable_from_source(home)
bpy.ops.wm.read_homefile()  # Blender's default scene: a cube, a lamp, a camera; Denoise on
scene = bpy.context.scene
scene.render.engine = "SPLAT_TRACER"
scene.render.resolution_x, scene.render.resolution_y = 48, 32
scene.cycles.samples = 4
scene.view_layers[0].cycles.denoising_store_passes = True
bpy.ops.render.render()
from blender_helpers import extension_module
print("SAMPLING", extension_module("blender.session").HISTORY[-1]["sampling"])
"""


def test_denoising_initialises_no_gpu_library(tmp_path):
    """In a fresh Blender (the first read of Cycles' `denoiser` enum would enumerate GPU
    devices and log 'CUEW initialization failed', which the version matrix reads as a
    failure): a default scene renders denoised, with Denoising Data on, and
    nothing mentions CUDA or CUEW."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    run = subprocess.run([sys.executable, "-c", CLEAN_PROCESS_RENDER], capture_output=True, text=True, timeout=300,
                         cwd=root, env={**os.environ, "PYTHONPATH": str(root / "tests" / "support")})
    assert run.returncode == 0, run.stderr[-2000:]
    log = run.stdout + run.stderr
    assert "SAMPLING" in log and "denoised by OpenImageDenoise (CPU)" in log, log[-2000:]
    assert "CUEW" not in log and "CUDA" not in log, log[-2000:]


def _inputs(w: int, h: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    color = (rng.random((h, w, 4)) ** 3 * 4).astype(np.float32)  # RGBA, as Combined: alpha ignored
    albedo = rng.random((h, w, 3)).astype(np.float32)
    n = rng.normal(size=(h, w, 3))
    return color, albedo, (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)


@pytest.mark.parametrize("prefilter", ["ACCURATE", "FAST"])
def test_the_denoiser_is_kept_across_frames_with_the_same_result(blender, prefilter):
    """The OIDN device and filters live across frames (creating them was most of a small
    frame's denoising time): a second frame creates none, a new size remakes the filters on
    the same device, other threads a new device -- and every result is bit-identical to a
    fresh device's."""
    denoise = extension_module("blender.denoise")
    if not denoise.available():
        pytest.skip("no OpenImageDenoise in this Blender")
    small, large = _inputs(48, 32), _inputs(80, 40, 1)

    def fresh(inputs, threads=0):
        denoise.release()
        return denoise.denoise(*inputs, prefilter, "HIGH", threads)

    first = fresh(small)
    created = dict(denoise.CREATED)
    second = denoise.denoise(*small, prefilter, "HIGH", 0)
    assert denoise.CREATED == created, (denoise.CREATED, created)
    np.testing.assert_array_equal(second, first)
    # The returned image is the caller's: the next frame does not overwrite it.
    assert not np.shares_memory(second, denoise.denoise(*small, prefilter, "HIGH", 0))
    np.testing.assert_array_equal(second, first)
    # A new size: same device, new filters; its result is a fresh device's, and back again.
    resized = denoise.denoise(*large, prefilter, "HIGH", 0)
    assert resized.shape == (40, 80, 3)
    assert denoise.CREATED["devices"] == created["devices"]
    assert denoise.CREATED["filters"] > created["filters"]
    np.testing.assert_array_equal(denoise.denoise(*small, prefilter, "HIGH", 0), first)
    np.testing.assert_array_equal(resized, fresh(large))
    # Fewer guides (the albedo only) remake the main filter, not the device.
    devices = denoise.CREATED["devices"]
    albedo_only = denoise.denoise(small[0], small[1], None, prefilter, "HIGH", 0)
    assert denoise.CREATED["devices"] == devices
    np.testing.assert_array_equal(albedo_only, fresh((small[0], small[1], None)))
    assert np.abs(albedo_only - first).max() > 0  # the test sees the guides change
    # Another thread count: a new device.
    devices = denoise.CREATED["devices"]
    denoise.denoise(*small, prefilter, "HIGH", 1)
    assert denoise.CREATED["devices"] == devices + 1
    denoise.release()
