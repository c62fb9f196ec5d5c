"""Texture coordinates and image projections (issue 24) through Blender, side by side with Cycles.

Scenes and helpers are test_node_materials.py's (80x80 px, 16 samples, black world, no
bounces). Tolerances (measured with bpy 5.0.1; each test also shows a wrong render fails):
- WINDOW_ATOL = 0.01: mean absolute difference per channel of an emissive floor whose colour
  is the Window coordinates (x red, y green) and a checker over them (blue), seen by a
  perspective camera with its lens shifted; the checker's anti-aliased edges are most of it.
  The same floor without the shift (Window as if the frame were not shifted) is > 5x further.
- TEXTURE_CORRELATION (0.95, the issue's bar) for the box, sphere and tube projections and
  for a UDIM image, as test_node_materials measures it.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from test_node_materials import SIZE, TEXTURE_CORRELATION, _both, _grid_image, _material, _setup, correlation, plane
from test_scene_export import cube, mesh_object, render, stats, uv_sphere

WINDOW_ATOL = 0.01


def _said(report, name):
    """The report's lines about material `name`, but for the one every emissive node tree
    gets (its emission is found by rays, not sampled as a light: these floors light nothing)."""
    return [line for line in report if name in line and "not sampled as a light" not in line]


def _emission(bpy, name):
    m = bpy.data.materials.new(name)
    nodes, links = m.node_tree.nodes, m.node_tree.links
    nodes.remove(nodes["Principled BSDF"])
    emission = nodes.new("ShaderNodeEmission")
    links.new(emission.outputs["Emission"], nodes["Material Output"].inputs["Surface"])
    return m, nodes, links, emission


def _window_floor(bpy, scene, kind="PERSP"):
    m, nodes, links, emission = _emission(bpy, "Window")
    coords, separate, checker, combine = (nodes.new(t) for t in (
        "ShaderNodeTexCoord", "ShaderNodeSeparateXYZ", "ShaderNodeTexChecker", "ShaderNodeCombineXYZ"))
    checker.inputs["Scale"].default_value = 3.0
    links.new(coords.outputs["Window"], separate.inputs["Vector"])
    links.new(coords.outputs["Window"], checker.inputs["Vector"])
    links.new(separate.outputs["X"], combine.inputs["X"])
    links.new(separate.outputs["Y"], combine.inputs["Y"])
    links.new(checker.outputs["Fac"], combine.inputs["Z"])
    links.new(combine.outputs["Vector"], emission.inputs["Color"])
    plane(bpy, "Floor", 12.0, (0, 0, 0), m)
    _setup(bpy, scene)
    cam = scene.camera
    cam.data.type, cam.data.lens, cam.data.ortho_scale = kind, 35.0, 6.0
    cam.data.shift_x, cam.data.shift_y = 0.3, -0.15
    cam.location, cam.rotation_euler = (0.5, -3.5, 2.5), (math.radians(60), 0, math.radians(8))
    bpy.context.view_layer.update()
    return cam


@pytest.mark.parametrize("kind", ["PERSP", "ORTHO"])
def test_window_coordinates_match_cycles(blender, empty_scene, tmp_path, kind):
    """Texture Coordinate > Window on a floor seen in perspective or orthographic with a
    shifted lens: the coordinates (red, green) and a checker over them (blue) as Cycles
    renders them."""
    bpy, scene = blender, empty_scene
    cam = _window_floor(bpy, scene, kind)
    ours, theirs, report = _both(bpy, scene, tmp_path, f"window_{kind.lower()}")
    diff = np.abs(ours - theirs).mean(axis=(0, 1))
    print(kind, "window: mean abs difference", diff, "correlation", correlation(ours, theirs))
    assert (diff <= WINDOW_ATOL).all(), diff
    assert correlation(ours, theirs) >= TEXTURE_CORRELATION
    assert not _said(report, "Window"), report
    # Window spans the frame: red runs 0..1 left to right, green 0..1 bottom to top.
    assert ours[SIZE // 2, 2, 0] < 0.1 and ours[SIZE // 2, -3, 0] > 0.9, ours[SIZE // 2, [2, -3], 0]
    assert ours[-3, SIZE // 2, 1] < 0.1
    # The frame's centre is (0.5, 0.5) whatever the shift (pixel SIZE // 2's centre: + 0.5 / SIZE).
    np.testing.assert_allclose(ours[SIZE // 2 - 1, SIZE // 2, :2], 0.5 + 0.5 / SIZE, atol=0.01)
    # Without the shift Cycles' Window would be the unshifted frame's: a wrong render fails.
    cam.data.shift_x, cam.data.shift_y = 0.0, 0.0
    scene.render.engine = "CYCLES"
    unshifted = render(bpy, scene, tmp_path / "window_unshifted.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    assert (np.abs(ours - unshifted).mean(axis=(0, 1))[:2] > 5 * WINDOW_ATOL).any()


def _image_node(nodes, links, shader, image, projection, vector=None, blend=0.0):
    tex = nodes.new("ShaderNodeTexImage")
    tex.image, tex.projection, tex.projection_blend, tex.interpolation = image, projection, blend, "Linear"
    if vector is not None:
        links.new(vector, tex.inputs["Vector"])
    links.new(tex.outputs["Color"], shader.inputs["Color" if "Color" in shader.inputs else "Base Color"])
    return tex


def _look_from(scene, location, rotation_deg, ortho_scale):
    cam = scene.camera
    cam.location, cam.rotation_euler = location, tuple(math.radians(a) for a in rotation_deg)
    cam.data.ortho_scale = ortho_scale
    import bpy

    bpy.context.view_layer.update()


@pytest.mark.parametrize("blend", [0.0, 0.3])
def test_box_projection_on_a_rotated_cube_matches_cycles(blender, empty_scene, tmp_path, blend):
    """An image box-projected (Object coordinates) on a cube and a smooth ball, both turned
    about all three axes, seen from above at an angle so that three faces show; with and
    without blending (the ball's normals between the axes show it). The flat projection of
    the same image fails."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "Box")
    coords = nodes.new("ShaderNodeTexCoord")
    tex = _image_node(nodes, links, emission, _grid_image(bpy, tmp_path, "disk"), "BOX", coords.outputs["Object"],
                      blend)
    obj = cube(bpy, "Cube", 1.0, (-0.6, 0.6, 0), m)
    obj.rotation_euler = tuple(math.radians(a) for a in (25, 35, 15))
    ball = uv_sphere(bpy, "Ball", 0.6, (0.6, -0.6, 0), m)  # every normal: the blend shows
    ball.rotation_euler = tuple(math.radians(a) for a in (-20, 10, 30))
    _setup(bpy, scene)
    _look_from(scene, (2.5, -2.5, 3.0), (50, 0, 45), 2.6)
    ours, theirs, report = _both(bpy, scene, tmp_path, f"box_{blend}")
    r = correlation(ours, theirs)
    print("correlation with Cycles", r)
    assert r >= TEXTURE_CORRELATION, r
    assert not _said(report, "Box"), report
    tex.projection = "FLAT"
    flat = render(bpy, scene, tmp_path / "box_flat.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    assert correlation(flat, theirs) < TEXTURE_CORRELATION


@pytest.mark.parametrize("projection", ["SPHERE", "TUBE"])
def test_sphere_and_tube_projections_match_cycles(blender, empty_scene, tmp_path, projection):
    """An image projected by Generated coordinates on a UV sphere seen from the side and
    above. A wrong projection fails: the other one is more than 3x as far from Cycles (mean
    absolute difference), and the flat one falls below the correlation."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, projection)
    coords = nodes.new("ShaderNodeTexCoord")
    tex = _image_node(nodes, links, emission, _grid_image(bpy, tmp_path, "disk"), projection,
                      coords.outputs["Generated"])
    uv_sphere(bpy, "Ball", 1.0, (0, 0, 0), m)
    _setup(bpy, scene)
    _look_from(scene, (0, -4.0, 2.5), (58, 0, 0), 2.4)
    ours, theirs, report = _both(bpy, scene, tmp_path, projection.lower())
    r = correlation(ours, theirs)
    print("correlation with Cycles", r)
    assert r >= TEXTURE_CORRELATION, r
    assert not _said(report, projection), report
    tex.projection = "TUBE" if projection == "SPHERE" else "SPHERE"
    other = render(bpy, scene, tmp_path / "other.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    near, far = np.abs(ours - theirs).mean(), np.abs(other - theirs).mean()
    print("mean abs difference", near, "the other projection's", far)
    assert far > 3 * near, (near, far)
    tex.projection = "FLAT"
    flat = render(bpy, scene, tmp_path / "flat.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    assert correlation(flat, theirs) < TEXTURE_CORRELATION


UDIM_COLOURS = {1001: (0.9, 0.3, 0.1), 1002: (0.1, 0.4, 0.9)}


def _linear(colour):
    """A byte sRGB image's colour as it renders (the sRGB standard's decoding)."""
    c = np.asarray(colour, np.float64)
    return np.where(c < 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _udim_image(bpy, tmp_path):
    """A two-tile UDIM made here: each tile a 4x4 image of one colour (tile 1002 with a
    lighter corner, so that the tile's own coordinates show), saved as tile files and loaded
    back as one tiled image (Blender finds the tiles from the <UDIM> token)."""
    for number, colour in UDIM_COLOURS.items():
        image = bpy.data.images.new(f"tile{number}", 4, 4)
        pixels = np.tile(np.float32([*colour, 1.0]), (4, 4, 1))
        if number == 1002:
            pixels[2:, 2:, :3] = 1.0  # top-right quarter white
        image.pixels.foreach_set(pixels.ravel())
        image.filepath_raw, image.file_format = str(tmp_path / f"udim.{number}.png"), "PNG"
        image.save()
        bpy.data.images.remove(image)
    tiled = bpy.data.images.load(str(tmp_path / "udim.1001.png"))
    tiled.source = "TILED"
    assert [t.number for t in tiled.tiles] == [1001, 1002] and "<UDIM>" in tiled.filepath_raw
    return tiled


def _udim_floor(bpy, material):
    """A 2x2 m floor whose UVs run 0..2 across (x) and 0..1.25 up (y): both tiles, and above
    them tiles the image lacks (1011, 1012: magenta, as in Cycles)."""
    import bmesh

    def build(bm):
        uv = bm.loops.layers.uv.new("UVMap")
        bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=1.0)
        for face in bm.faces:
            for loop in face.loops:
                x, y = loop.vert.co.x, loop.vert.co.y
                loop[uv].uv = (x + 1.0, (y + 1.0) * 0.625)

    return mesh_object(bpy, "Floor", build, (0, 0, 0), [material])


def test_udim_tiles_match_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "Udim")
    _image_node(nodes, links, emission, _udim_image(bpy, tmp_path), "FLAT")
    _udim_floor(bpy, m)
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "udim")
    r = correlation(ours, theirs)
    print("correlation with Cycles", r)
    assert r >= TEXTURE_CORRELATION, r
    assert not _said(report, "Udim"), report
    # Pixels at UV (u, v): row (1.25 - v) / 1.25 * SIZE from the top, column u / 2 * SIZE.
    at = {"1001": (60, 20), "1002": (60, 50), "1002 white": (35, 68), "no tile": (7, 40)}
    expected = {"1001": _linear(UDIM_COLOURS[1001]), "1002": _linear(UDIM_COLOURS[1002]), "1002 white": (1, 1, 1),
                "no tile": (1, 0, 1)}
    for name, (row, column) in at.items():
        np.testing.assert_allclose(ours[row, column], expected[name], atol=0.03, err_msg=name)
        np.testing.assert_allclose(theirs[row, column], expected[name], atol=0.03, err_msg=name + " (Cycles)")


def test_a_udim_tile_missing_on_disk_is_magenta_and_said(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "UdimMissing")
    image = _udim_image(bpy, tmp_path)
    (tmp_path / "udim.1002.png").unlink()
    _image_node(nodes, links, emission, image, "FLAT")
    _udim_floor(bpy, m)
    _setup(bpy, scene)
    ours = render(bpy, scene, tmp_path / "missing.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    np.testing.assert_allclose(ours[60, 20], _linear(UDIM_COLOURS[1001]), atol=0.03)
    np.testing.assert_allclose(ours[60, 50], (1, 0, 1), atol=0.03)
    assert [line for line in stats()["report"] if "1002" in line and "magenta" in line], stats()["report"]


def test_object_coordinates_of_another_object_match_cycles(blender, empty_scene, tmp_path):
    """Texture Coordinate > Object with an Empty chosen (moved, turned and scaled): a checker
    over the floor in the Empty's space, as Cycles renders it. The floor's own object space
    (the node without its object) fails."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "OtherObject")
    coords = nodes.new("ShaderNodeTexCoord")
    checker = nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 1.0
    links.new(coords.outputs["Object"], checker.inputs["Vector"])
    links.new(checker.outputs["Color"], emission.inputs["Color"])
    empty = bpy.data.objects.new("Handle", None)
    scene.collection.objects.link(empty)
    empty.location, empty.rotation_euler, empty.scale = (0.3, -0.2, 0.1), (0.2, -0.1, 0.6), (0.4, 0.6, 1.0)
    coords.object = empty
    plane(bpy, "Floor", 2.0, (0.1, 0.0, 0.0), m)
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "other_object")
    r = correlation(ours, theirs)
    print("correlation with Cycles", r)
    assert r >= TEXTURE_CORRELATION, r
    assert not _said(report, "OtherObject"), report
    coords.object = None
    own = render(bpy, scene, tmp_path / "own.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    assert correlation(own, theirs) < TEXTURE_CORRELATION


@pytest.mark.parametrize("kind", ["EQUIRECTANGULAR", "FISHEYE_EQUIDISTANT", "FISHEYE_EQUISOLID", "MIRRORBALL"])
def test_window_coordinates_of_a_panorama_match_cycles(blender, empty_scene, tmp_path, kind):
    """Window seen by a panoramic camera (its lens shifted, which Cycles' panorama Window
    does not follow) over a floor: the panorama's own coordinates of the direction to each
    point, as Cycles' direction_to_panorama gives them. Swapping red and green fails."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "PanoWindow")
    coords = nodes.new("ShaderNodeTexCoord")
    links.new(coords.outputs["Window"], emission.inputs["Color"])
    plane(bpy, "Floor", 30.0, (0, 0, 0), m)
    _setup(bpy, scene)
    cam = scene.camera
    cam.data.type, cam.data.panorama_type = "PANO", kind
    cam.data.fisheye_fov, cam.data.fisheye_lens, cam.data.sensor_width = math.radians(200), 8.0, 32.0
    cam.data.shift_x = 0.05
    cam.location, cam.rotation_euler = (0.0, 0.0, 1.0), (math.radians(60), 0, math.radians(-15))
    bpy.context.view_layer.update()
    ours, theirs, report = _both(bpy, scene, tmp_path, f"pano_window_{kind.lower()}")
    diff = np.abs(ours - theirs).mean(axis=(0, 1))
    print(kind, "mean abs difference", diff, "correlation", correlation(ours, theirs))
    assert (diff <= WINDOW_ATOL).all(), diff
    assert not _said(report, "PanoWindow"), report
    swapped = ours[..., [1, 0, 2]]
    assert (np.abs(swapped - theirs).mean(axis=(0, 1))[:2] > 5 * WINDOW_ATOL).any()


def test_window_coordinates_within_a_border_are_the_whole_frames(blender, empty_scene, tmp_path):
    """A render border does not change Window: 0..1 stays the whole frame's, in both engines
    (the border's pixels as Cycles renders them, and as the full frame has them)."""
    bpy, scene = blender, empty_scene
    _window_floor(bpy, scene)
    full = render(bpy, scene, tmp_path / "full.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    r = scene.render
    r.use_border, r.use_crop_to_border = True, False
    r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = 0.25, 0.75, 0.2, 0.6
    ours, theirs, _ = _both(bpy, scene, tmp_path, "window_border")
    inside = (slice(SIZE - 48, SIZE - 16), slice(20, 60))  # rows from the top, columns
    for image in (ours, theirs):
        assert np.abs(image[inside] - full[inside]).mean(axis=(0, 1)).max() <= WINDOW_ATOL
    assert ours[inside][..., :2].max() > 0.3  # the floor is in the border
    assert full[:, :15].max() > 0.1 and ours[:, :15].max() == 0  # and the border was rendered alone


def test_geometry_position_is_in_world_space_as_cycles(blender, empty_scene, tmp_path):
    """Geometry > Position is the world position (Cycles' P), with the camera (and so the
    render's local frame) far from the world's origin: the floor at z = 0 seen from z = 5,
    red and green the position x 0.4 + 0.5, blue its z + 0.5. The local frame's position
    (z = -5, blue 0) fails."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "WorldPosition")
    geometry, mapping = nodes.new("ShaderNodeNewGeometry"), nodes.new("ShaderNodeMapping")
    mapping.inputs["Location"].default_value = (0.5, 0.5, 0.5)
    mapping.inputs["Scale"].default_value = (0.4, 0.4, 1.0)
    links.new(geometry.outputs["Position"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], emission.inputs["Color"])
    plane(bpy, "Floor", 2.0, (0, 0, 0), m)
    _setup(bpy, scene)
    scene.camera.location = (0.3, -0.2, 5.0)
    bpy.context.view_layer.update()
    ours, theirs, report = _both(bpy, scene, tmp_path, "world_position")
    diff = np.abs(ours - theirs).mean(axis=(0, 1))
    print("position: mean abs difference", diff)
    assert (diff <= WINDOW_ATOL).all(), diff
    assert not _said(report, "WorldPosition"), report
    floor = theirs.sum(axis=-1) > 0.1
    assert abs(float(ours[floor][:, 2].mean()) - 0.5) < 0.02  # z = 0: the local frame's -5 would be black


@pytest.mark.parametrize("projection", ["EQUIRECTANGULAR", "MIRROR_BALL"])
@pytest.mark.parametrize("vector", ["Normal", None])
def test_environment_texture_in_a_material_matches_cycles(blender, empty_scene, tmp_path, projection, vector):
    """An Environment Texture inside a material, a ball's emission: by the Geometry's normal,
    or unlinked (the world position: the ball away from the origin sees it from aside). The
    image turned half a turn (Mapping about Z) fails."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "EnvMaterial")
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image, env.projection, env.interpolation = _grid_image(bpy, tmp_path, "disk"), projection, "Linear"
    mapping = None
    if vector is not None:
        geometry, mapping = nodes.new("ShaderNodeNewGeometry"), nodes.new("ShaderNodeMapping")
        mapping.vector_type = "VECTOR"
        links.new(geometry.outputs[vector], mapping.inputs["Vector"])
        links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    links.new(env.outputs["Color"], emission.inputs["Color"])
    uv_sphere(bpy, "Ball", 1.0, (0.4, 0.3, 1.2) if vector is None else (0, 0, 0), m)
    _setup(bpy, scene)
    _look_from(scene, (0.4, -4.0, 3.0) if vector is None else (0, -4.0, 2.5), (55, 0, 0), 2.6)
    ours, theirs, report = _both(bpy, scene, tmp_path, f"env_{projection}_{vector}")
    r = correlation(ours, theirs)
    print(projection, vector, "correlation with Cycles", r)
    assert r >= TEXTURE_CORRELATION, r
    assert not _said(report, "EnvMaterial"), report
    if mapping is not None:
        mapping.inputs["Rotation"].default_value = (0, 0, math.pi)
        turned = render(bpy, scene, tmp_path / "turned.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
        assert correlation(turned, theirs) < TEXTURE_CORRELATION


def test_a_uv_map_node_naming_another_map_matches_cycles(blender, empty_scene, tmp_path):
    """A UV Map node naming the floor's second UV map (turned and scaled against the first,
    the active render one) into a checker: Cycles' checker of that map. The active map's
    checker fails."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "SecondMap")
    uvmap = nodes.new("ShaderNodeUVMap")
    checker = nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 3.0
    links.new(uvmap.outputs["UV"], checker.inputs["Vector"])
    links.new(checker.outputs["Color"], emission.inputs["Color"])
    floor = plane(bpy, "Floor", 2.0, (0, 0, 0), m)
    second = floor.data.uv_layers.new(name="Second")
    first = floor.data.uv_layers["UVMap"]
    first.active_render = True
    for loop_uv, base in zip(second.uv, first.uv):
        u, v = base.vector
        loop_uv.vector = (0.8 * v + 0.1, 0.6 * (1 - u) + 0.3)
    uvmap.uv_map = "Second"
    _setup(bpy, scene)
    ours, theirs, report = _both(bpy, scene, tmp_path, "second_map")
    r = correlation(ours, theirs)
    print("correlation with Cycles", r)
    assert r >= TEXTURE_CORRELATION, r
    assert not _said(report, "SecondMap"), report
    uvmap.uv_map = ""
    active = render(bpy, scene, tmp_path / "active.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    assert correlation(active, theirs) < TEXTURE_CORRELATION


def test_a_udim_tile_that_cannot_be_read_is_magenta_and_said(blender, empty_scene, tmp_path):
    """A tile file that is not an image: that tile magenta (said), the frame renders."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "UdimBroken")
    image = _udim_image(bpy, tmp_path)
    (tmp_path / "udim.1002.png").write_bytes(b"not a png")
    _image_node(nodes, links, emission, image, "FLAT")
    _udim_floor(bpy, m)
    _setup(bpy, scene)
    ours = render(bpy, scene, tmp_path / "broken.exr", (SIZE, SIZE))["ViewLayer"]["Combined"][..., :3]
    np.testing.assert_allclose(ours[60, 20], _linear(UDIM_COLOURS[1001]), atol=0.03)
    np.testing.assert_allclose(ours[60, 50], (1, 0, 1), atol=0.03)
    assert [line for line in stats()["report"] if "1002" in line and "magenta" in line], stats()["report"]


def test_window_with_a_moving_camera_is_the_frames_as_in_cycles(blender, empty_scene, tmp_path):
    """With motion blur and the camera sliding sideways, Cycles' Window is the camera's at the
    frame's time (one transform): the checker over Window stays fixed to the floor and blurs
    with the camera's motion. Ours too: the blurred checker beside Cycles' (the blue channel)."""
    from test_motion_blur import _animate_x

    bpy, scene = blender, empty_scene
    cam = _window_floor(bpy, scene, "ORTHO")
    cam.data.shift_x = cam.data.shift_y = 0.0
    cam.location, cam.rotation_euler = (0, 0, 5), (0, 0, 0)
    _animate_x(cam, 0.0, 1.0)  # 1 m a frame: a checker cell (2 m) blurs over half of itself
    scene.frame_set(5)  # test_motion_blur's FRAME, between _animate_x's keys
    r = scene.render
    r.use_motion_blur, r.motion_blur_shutter = True, 1.0
    scene.cycles.samples = 256  # the blur's noise well below the tolerance
    ours, theirs, _ = _both(bpy, scene, tmp_path, "window_moving")
    diff = np.abs(ours - theirs).mean(axis=(0, 1))
    print("moving camera: mean abs difference", diff, "grey fractions",
          ((ours[..., 2] > 0.1) & (ours[..., 2] < 0.9)).mean(), ((theirs[..., 2] > 0.1) & (theirs[..., 2] < 0.9)).mean())
    assert (diff <= WINDOW_ATOL).all(), diff
    # The blur shows: blue between its two values over a band at each cell edge (a Window
    # following the camera at the ray's time would keep the checker sharp: grey only where
    # the pixels' edges cut a cell's, about a tenth of them).
    grey = ((theirs[..., 2] > 0.1) & (theirs[..., 2] < 0.9)).mean()
    assert grey > 0.3 and abs(((ours[..., 2] > 0.1) & (ours[..., 2] < 0.9)).mean() - grey) < 0.05
