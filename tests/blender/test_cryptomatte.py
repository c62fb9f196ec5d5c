"""Cryptomatte through Blender (issue 26, item 2): the engine's Object, Material and Asset
passes, read by Blender's own compositor node and laid out as Cycles lays them out.

One scene: a scan (a splat-cloud sphere, material 'Grey'), a ball (mesh, 'Red'), a box
(mesh, 'Blue', parented to the empty 'Rig': its asset) and two instances of a collection
holding a pebble (mesh, 'Grey': both instances are 'Pebble', as in Cycles), under a sun,
96x64 pixels, 16 samples, Levels 6. Rendered with the engine and with Cycles (CPU, no denoising) to
multilayer EXRs.

Tolerances (measured with bpy 5.0.1; each shown below to reject a wrong render):
- The compositor's Cryptomatte node, picking 'Ball' by name from the engine's EXR, against
  the ball's Object Index mask (the pixel-centre sample): 1 inside the mask eroded by 2
  pixels and 0 outside it dilated by 2 within INTERIOR_TOL; at the edges the matte is
  anti-aliased (the pixel filter's samples) and the mask is not, so there only the area is
  compared: the matte's sum within AREA_RTOL of the mask's pixel count. An id hashed
  wrongly (another seed) picks nothing: its area is 0.
- Against Cycles' EXR of the same scene: the same Crypto layers with the same RGBA
  channels, the same cryptomatte/<key>/ metadata keys, name, hash and conversion; every
  name of the engine's manifests in Cycles' with the same hash; and the ball's matte from
  both files within MATTE_TOL in the mean over the image.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.ndimage import binary_dilation, binary_erosion

from blender_helpers import add_camera, read_exr
from test_scene_export import cloud_sphere, cube, lamp, principled, uv_sphere

W, H, SAMPLES = 96, 64, 16
BALL, BOX, SCAN = 1, 2, 3  # pass indices
INTERIOR_TOL, AREA_RTOL, MATTE_TOL = 1e-3, 0.05, 0.02
KINDS = ("CryptoObject", "CryptoMaterial", "CryptoAsset")


def _scene(bpy):
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "SPLAT_TRACER"
    grey, red = principled(bpy, "Grey"), principled(bpy, "Red", (0.8, 0.1, 0.1))
    blue = principled(bpy, "Blue", (0.1, 0.1, 0.8))
    scan = cloud_sphere(bpy, "Scan", 3000, 0.6, (-1.0, 0, 0.6), grey)
    ball = uv_sphere(bpy, "Ball", 0.5, (0.6, 0, 0.5), red)
    box = cube(bpy, "Box", 0.8, (0.3, 1.2, 0.4), blue)
    rig = bpy.data.objects.new("Rig", None)
    scene.collection.objects.link(rig)
    box.parent = rig
    ball.pass_index, box.pass_index, scan.pass_index = BALL, BOX, SCAN
    pebbles = bpy.data.collections.new("Pebbles")  # not in the scene: only its instances render
    cube(bpy, "Pebble", 0.3, (0, 0, 0.15), grey, collection=pebbles)
    for i, x in enumerate((-0.2, 1.5)):
        instancer = bpy.data.objects.new(f"Pebbles {i}", None)
        instancer.instance_type, instancer.instance_collection = "COLLECTION", pebbles
        instancer.location = (x, -1.0, 0.0)
        scene.collection.objects.link(instancer)
    lamp(bpy, "SUN", rotation=(math.radians(-35), 0, 0), energy=3.0)
    add_camera(bpy, scene, (0, -5, 3), (math.radians(65), 0, 0))
    layer = scene.view_layers[0]
    layer.use_pass_cryptomatte_object = layer.use_pass_cryptomatte_material = True
    layer.use_pass_cryptomatte_asset = layer.use_pass_object_index = True
    c = scene.cycles
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling = SAMPLES, "CPU", False, False
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = W, H, 100
    r.image_settings.media_type = "MULTI_LAYER_IMAGE"
    r.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    r.image_settings.color_depth = "32"
    return scene


def _render(bpy, scene, path) -> tuple[dict, dict]:
    """The EXR's channels by name ('ViewLayer.CryptoObject00.R': (H, W), top row first) and
    its cryptomatte/ metadata."""
    import OpenEXR

    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    channels = {name: c.pixels for name, c in read_exr(path).items()}
    header = OpenEXR.File(str(path)).parts[0].header
    return channels, {k: v for k, v in header.items() if k.startswith("cryptomatte/")}


def _compositor_matte(bpy, scene, exr_path, name: str, path) -> np.ndarray:
    """Blender's Cryptomatte node (source: the EXR as an image, its CryptoObject layer),
    picking `name`; its Matte output as the composite, rendered once more to `path`."""
    tree = bpy.data.node_groups.new("Matte", "CompositorNodeTree")
    scene.compositing_node_group = tree
    node = tree.nodes.new("CompositorNodeCryptomatteV2")
    node.source = "IMAGE"
    node.image = bpy.data.images.load(str(exr_path))
    node.layer_name = "ViewLayer.CryptoObject"
    node.matte_id = name
    out = tree.nodes.new("NodeGroupOutput")
    tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    tree.links.new(node.outputs["Matte"], out.inputs[0])
    scene.render.use_compositing = True
    try:
        channels, _ = _render(bpy, scene, path)
    finally:
        scene.render.use_compositing = False
        scene.compositing_node_group = None
    return channels["Composite.Combined.R"]


def _layers(channels: dict, kind: str) -> list:
    return sorted({n.split(".")[1] for n in channels if n.startswith(f"ViewLayer.{kind}")})


def _matte(channels: dict, kind: str, matte_id: float) -> np.ndarray:
    """The coverage of `matte_id` (a float id) decoded from the EXR's layers of `kind`, as a
    compositor reads it: the sum of the coverages paired with that id."""
    total = np.zeros((H, W), np.float32)
    for layer in _layers(channels, kind):
        for i, c in (("r", "g"), ("b", "a")):  # Cycles' lower-case channel ids
            ids = channels[f"ViewLayer.{layer}.{i}"]
            total += np.where(ids == np.float32(matte_id), channels[f"ViewLayer.{layer}.{c}"], 0.0)
    return total


@pytest.fixture(scope="module")
def renders(blender, tmp_path_factory):
    bpy = blender
    folder = tmp_path_factory.mktemp("cryptomatte")
    scene = _scene(bpy)
    out = {"engine": _render(bpy, scene, folder / "engine.exr")}
    out["compositor"] = _compositor_matte(bpy, scene, folder / "engine.exr", "Ball", folder / "composite.exr")
    scene.view_layers[0].pass_cryptomatte_depth = 2
    out["levels2"] = _render(bpy, scene, folder / "levels2.exr")
    scene.view_layers[0].pass_cryptomatte_depth = 6
    scene.render.engine = "CYCLES"
    out["cycles"] = _render(bpy, scene, folder / "cycles.exr")
    return out


def _ball_regions(channels):
    mask = channels["ViewLayer.Object Index.X"] == BALL
    inside = binary_erosion(mask, iterations=2)
    outside = ~binary_dilation(mask, iterations=2)
    return mask, inside, outside


def test_compositor_node_extracts_the_object_index_mask(blender, renders):
    from splat_tracer.render import cryptomatte

    channels, _ = renders["engine"]
    mask, inside, outside = _ball_regions(channels)
    assert inside.sum() > 100 and outside.sum() > 2000  # the ball is in view, and not all of it
    matte = renders["compositor"]
    print(f"compositor matte: inside min {matte[inside].min():.4f}, outside max {matte[outside].max():.4f}, "
          f"area {matte.sum():.1f} vs mask {mask.sum()}")
    assert matte[inside].min() > 1 - INTERIOR_TOL
    assert matte[outside].max() < INTERIOR_TOL
    assert abs(matte.sum() - mask.sum()) < AREA_RTOL * mask.sum()
    # The node reads what the engine wrote: the same matte decoded here from the file.
    np.testing.assert_allclose(matte, _matte(channels, "CryptoObject", cryptomatte.name_id("Ball")), atol=1e-6)
    # An id hashed wrongly (MurmurHash3 with seed 1) picks nothing.
    wrong = cryptomatte.hash_to_float(cryptomatte.murmur3_32(b"Ball", 1))
    assert _matte(channels, "CryptoObject", wrong).sum() == 0.0


def test_material_and_asset_mattes(blender, renders):
    from splat_tracer.render import cryptomatte

    channels, _ = renders["engine"]
    ball = _matte(channels, "CryptoObject", cryptomatte.name_id("Ball"))
    box = _matte(channels, "CryptoObject", cryptomatte.name_id("Box"))
    # One material each: 'Red' is the ball's matte, 'Blue' the box's.
    np.testing.assert_allclose(_matte(channels, "CryptoMaterial", cryptomatte.name_id("Red")), ball, atol=1e-6)
    np.testing.assert_allclose(_matte(channels, "CryptoMaterial", cryptomatte.name_id("Blue")), box, atol=1e-6)
    # The box's asset is its parent 'Rig'; the ball, without a parent, is its own.
    np.testing.assert_allclose(_matte(channels, "CryptoAsset", cryptomatte.name_id("Rig")), box, atol=1e-6)
    np.testing.assert_allclose(_matte(channels, "CryptoAsset", cryptomatte.name_id("Ball")), ball, atol=1e-6)
    assert box.sum() > 50
    assert _matte(channels, "CryptoAsset", cryptomatte.name_id("Box")).sum() == 0.0


def test_layout_and_manifest_as_cycles(blender, renders):
    from splat_tracer.render import cryptomatte

    ours, our_meta = renders["engine"]
    cycles, cycles_meta = renders["cycles"]
    for kind in KINDS:
        assert _layers(ours, kind) == _layers(cycles, kind) == [f"{kind}{i:02d}" for i in range(3)]
        for layer in _layers(ours, kind):
            assert sorted(n for n in ours if n.startswith(f"ViewLayer.{layer}.")) == sorted(
                n for n in cycles if n.startswith(f"ViewLayer.{layer}."))
    assert set(our_meta) == set(cycles_meta)
    for key, value in our_meta.items():
        if key.endswith("/manifest"):
            theirs = json.loads(cycles_meta[key])
            mine = json.loads(value)
            assert mine and all(theirs.get(name) == h for name, h in mine.items()), (key, mine, theirs)
        else:
            assert value == cycles_meta[key], key
    # The pixels carry the same ids: the ball's matte from both files.
    ball = cryptomatte.name_id("Ball")
    difference = np.abs(_matte(ours, "CryptoObject", ball) - _matte(cycles, "CryptoObject", ball)).mean()
    print(f"ball matte, mean |engine - Cycles| = {difference:.4f}")
    assert _matte(cycles, "CryptoObject", ball).sum() > 100
    assert difference < MATTE_TOL


def test_instances_share_their_object_name(blender, renders):
    from scipy.ndimage import label

    from splat_tracer.render import cryptomatte

    ours, meta = renders["engine"]
    cycles, _ = renders["cycles"]
    pebble = cryptomatte.name_id("Pebble")
    for channels in (ours, cycles):
        matte = _matte(channels, "CryptoObject", pebble)
        assert label(matte > 0.5)[1] == 2  # both instances, one name
        np.testing.assert_array_equal(_matte(channels, "CryptoAsset", pebble), matte)
    difference = np.abs(_matte(ours, "CryptoObject", pebble) - _matte(cycles, "CryptoObject", pebble)).mean()
    print(f"pebbles matte, mean |engine - Cycles| = {difference:.4f}")
    assert difference < MATTE_TOL
    manifests = [json.loads(v) for k, v in meta.items() if k.endswith("/manifest")]
    assert all("Pebbles 0" not in m for m in manifests)  # the instancer is not a name


def test_levels_set_the_layer_count(blender, renders):
    six, _ = renders["engine"]
    two, _ = renders["levels2"]
    for kind in KINDS:
        assert len(_layers(two, kind)) == 1 and len(_layers(six, kind)) == 3


def test_the_engines_passes_panel_shows_the_settings(blender, empty_scene):
    from types import SimpleNamespace

    from test_method_settings import _Layout

    bpy = blender
    panel = bpy.types.SPLAT_TRACER_PT_passes_cryptomatte
    assert panel.poll(bpy.context)
    drawn = []
    panel.draw(SimpleNamespace(layout=_Layout(drawn)), SimpleNamespace(view_layer=empty_scene.view_layers[0]))
    assert drawn == ["use_pass_cryptomatte_object", "use_pass_cryptomatte_material", "use_pass_cryptomatte_asset",
                     "pass_cryptomatte_depth"]
    empty_scene.render.engine = "CYCLES"
    assert not panel.poll(bpy.context)
