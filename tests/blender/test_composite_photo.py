"""A scan on a shadow-catcher floor composited over a photograph by Blender's compositor
(issue 26), side by side with Cycles: what tools/composite_images.py makes for the user
guide, at a test's size.

The scene is test_shadow_catcher.py's (a splat-cloud sphere over a floor, a slanted sun, a
grey world), with Film > Transparent, the floor marked Shadow Catcher, and the compositor
of tools/composite_images.py: Render Layers' Image laid with Alpha Over on a photograph --
here a synthetic plate (a colour gradient written to a float EXR), so that nothing depends on
the pixels of an image shipped with Blender. Each engine renders and composites at 128 x 96
with 64 samples (Cycles: CPU, no denoising, no adaptive sampling); the composite is read
back from the saved EXR (scene linear, before the view transform). The regions are Cycles'
own, from its Object Index and alpha rendered with the compositor off: "scan", "shadow"
(Cycles' alpha > 0.45 on the floor, eroded), "floor" (the floor 3 pixels and more away from
any pixel where Cycles' alpha > 0.02) and "background" (the world, index 0).

Tolerances, against Cycles' composite (each measured with bpy 5.0.1, and shown below to
reject a floor that is not a catcher):
- SHADOW_TOL = 0.06 on the darkening of the photograph in the shadow, 1 - composite / plate
  averaged (test_shadow_catcher.py's ALPHA_TOL): measured 0.017 apart;
- PLATE_TOL = 0.01 on the mean absolute difference from the photograph on the unshadowed
  floor and the background (the photograph untouched there): measured 0.0001 and 0.0;
- SCAN_RTOL = 0.1 on the scan's mean colour (the cloud's discs against Cycles' spheres):
  measured 2.5 % apart.
With the catcher flag off, the floor is off by 0.57 from the photograph and the shadow's
darkening by 0.64.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import binary_dilation

from test_scene_export import INDEX, erode, render
from test_shadow_catcher import FLOOR, SCAN, _scene

from tools.composite_images import alpha_over_compositor

W, H = 128, 96
SHADOW_TOL, PLATE_TOL, SCAN_RTOL = 0.06, 0.01, 0.1


def photograph() -> np.ndarray:
    """The plate, (H, W, 3) top row first: a colour gradient (any image would do)."""
    y, x = np.mgrid[:H, :W] / np.array([H, W])[:, None, None]
    return np.stack([0.2 + 0.6 * x, np.full_like(x, 0.4), 0.8 - 0.5 * y], axis=-1).astype(np.float32)


def save_exr(path, rgb) -> None:
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {c: np.ascontiguousarray(rgb[..., i]) for i, c in enumerate("RGB")}
    with OpenEXR.File(header, channels) as f:
        f.write(str(path))


def read_exr(path) -> np.ndarray:
    """A single-layer EXR's RGB, top row first."""
    import OpenEXR

    channels = OpenEXR.File(str(path), separate_channels=True).parts[0].channels
    return np.stack([channels[c].pixels for c in "RGB"], axis=-1).astype(np.float64)


@pytest.fixture(scope="module")
def composites(blender, tmp_path_factory):
    """composites(engine, catcher) -> (composite, passes of the render with the compositor off)."""
    bpy = blender
    folder = tmp_path_factory.mktemp("composite")
    scene, floor, _scan = _scene(bpy)
    plate_path = folder / "photograph.exr"
    save_exr(plate_path, photograph())
    tree = alpha_over_compositor(bpy, scene, plate_path)
    cache = {}

    def get(engine, catcher=True):
        if (engine, catcher) not in cache:
            scene.render.engine = engine
            floor.is_shadow_catcher = catcher
            scene.render.film_transparent = True
            scene.render.use_compositing = False
            scene.compositing_node_group = None
            passes = render(bpy, scene, folder / f"passes_{engine}_{catcher}.exr", (W, H))["ViewLayer"]
            scene.compositing_node_group, scene.render.use_compositing = tree, True
            r = scene.render
            r.image_settings.media_type = "IMAGE"
            r.image_settings.file_format = "OPEN_EXR"
            r.image_settings.color_depth = "32"
            r.filepath = str(folder / f"composite_{engine}_{catcher}.exr")
            bpy.ops.render.render(write_still=True)
            cache[engine, catcher] = read_exr(r.filepath), passes
        return cache[engine, catcher]
    return get


def regions(composites) -> dict:
    cycles = composites("CYCLES")[1]
    alpha, index = cycles["Combined"][..., 3], cycles[INDEX]
    floor = erode(index == FLOOR, 2)
    ours_index = composites("SPLAT_TRACER", False)[1][INDEX]
    return {"scan": erode(index == SCAN, 2) & erode(ours_index == SCAN, 2),
            "shadow": floor & erode(alpha > 0.45, 1),
            "floor": floor & ~binary_dilation(alpha > 0.02, iterations=3),
            "background": erode(index == 0, 2) & erode(ours_index == 0, 2)}


def differences(ours: np.ndarray, cycles: np.ndarray, masks: dict) -> dict:
    """Per region, how far our composite is from Cycles' (see the module's docstring)."""
    plate = photograph()
    dark = lambda c: 1.0 - (c[masks["shadow"]] / plate[masks["shadow"]]).mean()  # noqa: E731
    return {"shadow": abs(dark(ours) - dark(cycles)),
            "floor": np.abs(ours[masks["floor"]] - plate[masks["floor"]]).mean(),
            "background": np.abs(ours[masks["background"]] - plate[masks["background"]]).mean(),
            "scan": abs(ours[masks["scan"]].mean() / cycles[masks["scan"]].mean() - 1.0)}


TOLERANCES = {"shadow": SHADOW_TOL, "floor": PLATE_TOL, "background": PLATE_TOL, "scan": SCAN_RTOL}


def test_a_scan_composited_over_a_photograph_matches_cycles_region_by_region(composites):
    masks = regions(composites)
    assert all(m.sum() > 100 for m in masks.values()), {k: int(m.sum()) for k, m in masks.items()}
    cycles, ours = composites("CYCLES")[0], composites("SPLAT_TRACER")[0]
    plate = photograph()
    # Cycles' composite itself: darkened in the shadow, the plate untouched elsewhere.
    assert 1.0 - (cycles[masks["shadow"]] / plate[masks["shadow"]]).mean() > 0.3
    for region in ("floor", "background"):
        assert np.abs(cycles[masks[region]] - plate[masks[region]]).mean() < PLATE_TOL
    diff = differences(ours, cycles, masks)
    print("differences from Cycles' composite:", {k: round(float(v), 4) for k, v in diff.items()})
    assert all(diff[k] < TOLERANCES[k] for k in diff), diff
    # The floor without the catcher flag (an opaque grey floor over the photograph) fails.
    plain = differences(composites("SPLAT_TRACER", False)[0], cycles, masks)
    print("differences with the catcher off:", {k: round(float(v), 4) for k, v in plain.items()})
    assert plain["floor"] > 10 * PLATE_TOL and plain["shadow"] > SHADOW_TOL
