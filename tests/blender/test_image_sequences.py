"""Image files read without Blender images (issue 24): image sequences in an Image Texture,
side by side with Cycles, and images.read_file (UDIM tiles, sequence frames) against the
pixels Blender loads from the same files.

Scenes are test_node_materials.py's (80x80 px, 16 samples, black world, no bounces): an
emissive floor filling the view, its colour an Image Texture of a 3-frame PNG sequence made
here, one flat colour a frame. FRAME_ATOL = 0.01: the mean colour of our floor and of
Cycles' beside the colour of the frame expected; the frames' colours are > 0.3 apart in some
channel, so another frame's colour fails by 30x.
"""
from __future__ import annotations

import numpy as np
import pytest

from test_node_coordinates import _emission, _linear
from test_node_materials import _both, _setup, plane
from test_scene_export import stats

FRAME_ATOL = 0.01
# The sequence's frames 1..3, sRGB-encoded bytes.
FRAME_COLOURS = {1: (0.9, 0.3, 0.1), 2: (0.1, 0.8, 0.2), 3: (0.2, 0.3, 0.9)}


def _sequence(bpy, tmp_path, name="seq_"):
    """A 3-frame PNG sequence (4x4 px, one colour a frame) loaded as a sequence image."""
    for number, colour in FRAME_COLOURS.items():
        image = bpy.data.images.new(f"frame{number}", 4, 4)
        image.pixels.foreach_set(np.tile(np.float32([*colour, 1.0]), 16))
        image.filepath_raw, image.file_format = str(tmp_path / f"{name}{number:04d}.png"), "PNG"
        image.save()
        bpy.data.images.remove(image)
    image = bpy.data.images.load(str(tmp_path / f"{name}0001.png"))
    image.source = "SEQUENCE"
    return image


def _sequence_floor(bpy, scene, tmp_path):
    m, nodes, links, emission = _emission(bpy, "Sequence")
    tex = nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = _sequence(bpy, tmp_path), "Closest"
    links.new(tex.outputs["Color"], emission.inputs["Color"])
    tex.image_user.frame_duration = 3
    plane(bpy, "Floor", 2.0, (0, 0, 0), m)
    _setup(bpy, scene)
    return tex.image_user


def _mean(rgb):
    return rgb.reshape(-1, 3).mean(0)


@pytest.mark.parametrize("start, offset, cyclic, frames", [
    (1, 0, False, {1: 1, 2: 2, 3: 3, 5: 3}),  # held at the last frame after the sequence
    (2, 1, False, {2: 2, 3: 3}),  # starts at scene frame 2, one frame on
    (1, 0, True, {4: 1, 5: 2}),  # wraps around
])
def test_a_sequence_renders_cycles_frame(blender, empty_scene, tmp_path, start, offset, cyclic, frames):
    bpy, scene = blender, empty_scene
    user = _sequence_floor(bpy, scene, tmp_path)
    user.frame_start, user.frame_offset, user.use_cyclic = start, offset, cyclic
    for scene_frame, shown in frames.items():
        scene.frame_set(scene_frame)
        ours, theirs, report = _both(bpy, scene, tmp_path, f"seq{scene_frame}")
        expected = _linear(FRAME_COLOURS[shown])
        print(scene_frame, "ours", _mean(ours), "Cycles", _mean(theirs), "expected", expected)
        np.testing.assert_allclose(_mean(theirs), expected, atol=FRAME_ATOL)
        np.testing.assert_allclose(_mean(ours), expected, atol=FRAME_ATOL)
        assert not [line for line in report if "Sequence" in line and "not sampled" not in line], report
        for other, colour in FRAME_COLOURS.items():  # another frame's colour is far outside
            if other != shown:
                assert np.abs(_mean(ours) - _linear(colour)).max() > 30 * FRAME_ATOL


def test_a_missing_frame_is_magenta_and_said(blender, empty_scene, tmp_path):
    """Offset past the files: Cycles renders magenta, and so do we, said."""
    bpy, scene = blender, empty_scene
    user = _sequence_floor(bpy, scene, tmp_path)
    user.frame_offset = 5
    scene.frame_set(1)
    ours, theirs, report = _both(bpy, scene, tmp_path, "missing")
    np.testing.assert_allclose(_mean(theirs), (1, 0, 1), atol=FRAME_ATOL)
    np.testing.assert_allclose(_mean(ours), (1, 0, 1), atol=FRAME_ATOL)
    assert [line for line in report if "frame 6" in line and "magenta" in line], report


def test_sequence_frames_and_paths_are_blenders(blender, empty_scene, tmp_path):
    """sequence_frame is Blender's frame_current for an auto-refreshed Image User (Blender
    computes it in the evaluated material on frame change), over starts, offsets, cyclic or
    not, before and after the sequence; sequence_path is Blender's filepath_from_user."""
    from splat_tracer.blender.export import nodes as export_nodes

    bpy, scene = blender, empty_scene
    user = _sequence_floor(bpy, scene, tmp_path)
    image = bpy.data.materials["Sequence"].node_tree.nodes["Image Texture"].image
    user.use_auto_refresh = True
    checked = 0
    for start, offset, cyclic, count in [(1, 0, False, 3), (3, 2, False, 3), (1, -1, True, 3), (-2, 4, True, 5)]:
        user.frame_start, user.frame_offset, user.use_cyclic, user.frame_duration = start, offset, cyclic, count
        for frame in range(-4, 12):
            scene.frame_set(frame)
            evaluated = bpy.data.materials["Sequence"].evaluated_get(bpy.context.evaluated_depsgraph_get())
            blenders = evaluated.node_tree.nodes["Image Texture"].image_user.frame_current
            assert export_nodes.sequence_frame(user, frame) == blenders, (start, offset, cyclic, frame)
            checked += 1
    assert checked == 64
    for name in ("f_0001.png", "shot12_v3_0042.exr", "a7.b.png", "x9_final.jpg"):
        image.filepath_raw = str(tmp_path / name)
        for number in (0, 1, 7, 123, 12345):
            user.frame_current = number
            assert export_nodes.sequence_path(image.filepath_raw, number) == image.filepath_from_user(
                image_user=user), (name, number)


def test_read_file_gives_blenders_pixels(blender, empty_scene, tmp_path):
    """images.read_file of a file is images.read of that file loaded by Blender: 8-bit files
    exactly (one step of 1/255 when un-premultiplied), deeper ones (16-bit PNG and TIFF,
    float EXR; alpha below 1) within 1e-4, in the sRGB, linear and data colour spaces and
    every Alpha mode of the image (the tiles and frames follow the image's, as Blender loads
    them)."""
    from splat_tracer.blender.export import images

    bpy, scene = blender, empty_scene
    rng = np.random.default_rng(7)
    source = rng.random((5, 7, 4)).astype(np.float32)
    source[..., 3] = 0.2 + 0.8 * rng.random((5, 7))
    settings = scene.render.image_settings
    for name, fmt, depth, mode in [("a8.png", "PNG", "8", "RGBA"), ("a.jpg", "JPEG", "8", "RGB"),
                                   ("a16.png", "PNG", "16", "RGBA"), ("a16.tif", "TIFF", "16", "RGBA"),
                                   ("a.exr", "OPEN_EXR", "32", "RGBA")]:
        made = bpy.data.images.new("made", 7, 5, alpha=True, float_buffer=depth != "8")
        made.pixels.foreach_set(source.ravel())
        settings.file_format, settings.color_mode, settings.color_depth = fmt, mode, depth
        made.save_render(str(tmp_path / name), scene=scene)
        bpy.data.images.remove(made)
        for space in ("sRGB", "Linear Rec.709", "Non-Color"):
            # The image's Alpha mode as Blender loads it (None: the one a loaded image gets).
            for alpha_mode in (None, "STRAIGHT", "PREMUL", "CHANNEL_PACKED", "NONE"):
                loaded = bpy.data.images.load(str(tmp_path / name), check_existing=False)
                loaded.colorspace_settings.name = space
                if alpha_mode is not None:
                    loaded.alpha_mode = alpha_mode
                    loaded.reload()
                theirs = images.read(loaded, print)
                ours = images.read_file(str(tmp_path / name), space, loaded.name, print, loaded.alpha_mode)
                assert (ours.srgb, ours.is_float) == (theirs.srgb, theirs.is_float) == (ours.srgb, depth != "8")
                # Bytes exactly, except that Blender's byte un-premultiply rounds a few values the
                # other way: one step of 1/255 at most there.
                atol = (1.0 / 255 + 1e-6 if loaded.alpha_mode == "PREMUL" else 0.0) if depth == "8" else 1e-4
                np.testing.assert_allclose(ours.values, theirs.values, atol=atol,
                                           err_msg=f"{name} {space} {loaded.alpha_mode}")
                bpy.data.images.remove(loaded)
    assert images.read_file(str(tmp_path / "none.png"), "sRGB", "none", print) is None
    (tmp_path / "bad.png").write_bytes(b"not a png")
    assert images.read_file(str(tmp_path / "bad.png"), "sRGB", "bad", print) is None


def test_a_movie_is_said_and_left_out(blender, empty_scene, tmp_path):
    """A movie in an Image Texture is not read (said); the frame renders."""
    from test_scene_export import render

    bpy, scene = blender, empty_scene
    _sequence_floor(bpy, scene, tmp_path)
    bpy.data.materials["Sequence"].node_tree.nodes["Image Texture"].image.source = "MOVIE"
    render(bpy, scene, tmp_path / "movie.exr", (16, 16))
    assert [line for line in stats()["report"] if "Sequence" in line and "movie" in line], stats()["report"]
