"""Skip, don't refuse (issue 22): one object, point or lamp the renderer cannot use is left out
(or clamped) and named once, with the reason, in the render report; the frame renders.

Each test renders a scene of good objects with the bad one, then the same scene without it
(hidden, or rebuilt without the bad points or faces): the good objects' pixels must be the
same. The headlight lights the scenes (one camera ray per sample, no secondary rays), so
that an object left out changes nothing else; the lamp tests light with lamps.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from blender_helpers import add_camera, extension_module, render_to_exr
from geometry import fibonacci_sphere

W, H = 64, 48


def session():
    return extension_module("blender.session")


def report() -> list:
    """The last frame's report lines."""
    return session().HISTORY[-1]["report"]


def said_once(lines: list, *parts: str) -> None:
    """Exactly one line holds every one of `parts`."""
    hits = [line for line in lines if all(p in line for p in parts)]
    assert len(hits) == 1, (parts, lines)


def cloud(name, n=2000, radius=0.6, location=(0, 0, 0), colours=None, edit=None):
    """A closed splat-cloud sphere; edit(positions, normals, radii, colours) may spoil it
    (the arrays are float32 copies) before the object is made."""
    cloud_object = extension_module("blender.cloud_object")
    p, nrm = fibonacci_sphere(n, radius)
    p, nrm = p.astype(np.float32), nrm.astype(np.float32)
    radii = np.full(n, 1.5 * math.sqrt(4 * math.pi * radius ** 2 / n), np.float32)
    if colours is not None:
        colours = np.array(colours, np.float32)
    if edit is not None:
        p, nrm, radii, colours = edit(p, nrm, radii, colours)
    obj = cloud_object.create_cloud_object(name, p, nrm, radii, colours, location=location)
    obj.splat_tracer.closed = True
    return obj


def cube(bpy, name, size=0.8, location=(0, 0, 0), edit=None):
    """A mesh cube; edit(bm) may change it with bmesh first."""
    import bmesh

    mesh = bpy.data.meshes.new(name)
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=size)
    if edit is not None:
        edit(bm)
    bm.to_mesh(mesh)
    bm.free()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    return obj


def good_scene(bpy, scene, headlight=True):
    """A cloud on the left and a mesh cube on the right, seen by the camera; returns them."""
    a = cloud("Good Cloud", location=(-0.9, 0, 0))
    b = cube(bpy, "Good Cube", location=(0.9, 0, 0))
    add_camera(bpy, scene, (0, -5, 0), (math.radians(90), 0, 0))
    if headlight:
        scene.splat_tracer.lighting = "HEADLIGHT"
    scene.cycles.samples = 4
    return a, b


def rgba(bpy, scene, path):
    out = render_to_exr(bpy, scene, path, W, H, passes=False)
    assert session().HISTORY[-1]["completed"]
    return out["rgba"]


# --------------------------------------------------------------------------------------
# Objects scaled to 0.

@pytest.mark.parametrize("kind", ["mesh", "cloud"])
@pytest.mark.parametrize("axis", [0, 1, 2])
def test_an_object_scaled_to_zero_is_left_out_and_named(blender, empty_scene, tmp_path, kind, axis):
    bpy, scene = blender, empty_scene
    good_scene(bpy, scene)
    bad = cube(bpy, "Flat", location=(0, 0, 0.8)) if kind == "mesh" else cloud("Flat", location=(0, 0, 0.8))
    scale = [1.0, 1.0, 1.0]
    scale[axis] = 0.0
    bad.scale = scale
    with_bad = rgba(bpy, scene, tmp_path / "with.exr")
    said_once(report(), "object 'Flat'", "singular (scaled to 0 along an axis)", "not rendered")
    bad.hide_render = True
    without = rgba(bpy, scene, tmp_path / "without.exr")
    np.testing.assert_array_equal(with_bad, without)
    assert (without[..., 3] > 0).sum() > 200  # the good objects are there


@pytest.mark.parametrize("scale", [1e-30, 1e20])
def test_an_object_scaled_beyond_the_limits_is_left_out_and_named(blender, empty_scene, tmp_path, scale):
    """Not singular, but its inverse (scale 1e-30) or itself (1e20) is beyond float32's
    reach of the core."""
    bpy, scene = blender, empty_scene
    good_scene(bpy, scene)
    bad = cube(bpy, "Extreme", location=(0, 0, 0.8))
    bad.scale = (scale, scale, scale)
    with_bad = rgba(bpy, scene, tmp_path / "with.exr")
    said_once(report(), "object 'Extreme'", "renderer's limit", "not rendered")
    bad.hide_render = True
    np.testing.assert_array_equal(with_bad, rgba(bpy, scene, tmp_path / "without.exr"))


def test_an_animation_scaling_an_object_to_zero_renders_every_frame(blender, empty_scene, tmp_path):
    """Scale 1, 0, 1 on frames 1-3 (exact on the keys): every frame renders; only frame 2
    leaves the object out."""
    bpy, scene = blender, empty_scene
    good_scene(bpy, scene)
    bad = cube(bpy, "Pulse", location=(0, 0, 0.8))
    for frame, s in ((1, 1.0), (2, 0.0), (3, 1.0)):
        bad.scale = (s, s, s)
        bad.keyframe_insert("scale", frame=frame)
    scene.frame_start, scene.frame_end = 1, 3
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = W, H, 100
    r.image_settings.media_type = "IMAGE"
    r.image_settings.file_format = "PNG"
    r.filepath = str(tmp_path / "frame_")
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    frames = session().HISTORY[-3:]
    assert [f["frame"] for f in frames] == [1, 2, 3] and all(f["completed"] for f in frames)
    assert [f["instances"] for f in frames] == [3, 2, 3]
    said_once(frames[1]["report"], "object 'Pulse'", "scaled to 0")
    assert not any("Pulse" in line for f in (frames[0], frames[2]) for line in f["report"])
    assert len(list(tmp_path.glob("frame_*.png"))) == 3


# --------------------------------------------------------------------------------------
# Bad points among good ones.

def _spoil(what):
    """An edit for cloud(): point 5 (and for some, point 9) made bad in one attribute."""
    def edit(p, nrm, radii, colours):
        if what == "nan colour":
            colours[5, 0] = np.nan
        elif what == "inf colour":
            colours[5, 2] = np.inf
        elif what == "nan alpha":
            colours[:, 3] = 0.5  # a cloud that is not opaque keeps its alpha
            colours[5, 3] = np.nan
        elif what == "huge position":
            p[5] = (1e19, 0.0, 0.0)
        elif what == "huge radius":
            radii[5] = 1e30
        elif what == "3dgs radius":
            radii[5] = 2.0 * math.exp(44.0)  # a Gaussian's scales of 88 and 0: sqrt(e^88), about 1.6e19
        return p, nrm, radii, colours
    return edit


REASONS = {"nan colour": "a colour that is not finite", "inf colour": "a colour that is not finite",
           "nan alpha": "a colour that is not finite", "huge position": "a position beyond the renderer's limit",
           "huge radius": "a radius beyond the renderer's limit", "3dgs radius": "a radius beyond the renderer's limit"}


@pytest.mark.parametrize("what", list(REASONS))
def test_a_bad_point_is_left_out_counted_and_the_rest_renders(blender, empty_scene, tmp_path, what):
    bpy, scene = blender, empty_scene
    good_scene(bpy, scene)
    colours = np.tile(np.float32([0.9, 0.3, 0.1, 1.0]), (2000, 1))
    bad = cloud("Speckled", location=(0, 0, 0.8), colours=colours, edit=_spoil(what))
    with_bad = rgba(bpy, scene, tmp_path / "with.exr")
    said_once(report(), "point cloud 'Speckled': 1 points have", REASONS[what], "(first: point 5)", "not rendered")
    # The same cloud without point 5.
    bpy.data.objects.remove(bad)

    def without_point_5(p, nrm, radii, colours):
        spoilt = _spoil(what)(p, nrm, radii, colours)
        keep = np.arange(len(p)) != 5
        return tuple(a[keep] for a in spoilt)

    cloud("Clean", location=(0, 0, 0.8), colours=colours, edit=without_point_5)
    np.testing.assert_array_equal(with_bad, rgba(bpy, scene, tmp_path / "without.exr"))


def test_a_radius_beyond_the_limit_after_the_radius_factor_is_left_out(blender, empty_scene, tmp_path):
    """A radius of 1e17 is fine alone; the Radius Factor's maximum (100) puts it beyond the
    core's limit. The factor itself has a hard maximum: 1e30 is clamped."""
    bpy, scene = blender, empty_scene
    good_scene(bpy, scene)
    scene.splat_tracer.radius_factor = 1e30
    assert scene.splat_tracer.radius_factor == 100.0

    def big(p, nrm, radii, colours):
        radii[7] = 1e17
        return p, nrm, radii, colours

    cloud("Big", location=(0, 0, 0.8), edit=big)
    rgba(bpy, scene, tmp_path / "big.exr")
    said_once(report(), "point cloud 'Big': 1 points have", "a radius beyond the renderer's limit (1e+18) after the "
              "Radius Factor (100)", "(first: point 7)")


def test_a_cloud_whose_every_point_is_bad_is_left_out_and_named(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    good_scene(bpy, scene)

    def all_nan(p, nrm, radii, colours):
        colours[:, 1] = np.nan
        return p, nrm, radii, colours

    bad = cloud("Hopeless", location=(0, 0, 0.8), colours=np.ones((2000, 4)), edit=all_nan)
    with_bad = rgba(bpy, scene, tmp_path / "with.exr")
    said_once(report(), "point cloud 'Hopeless': none of its 2,000 points can be rendered; not rendered")
    bad.hide_render = True
    np.testing.assert_array_equal(with_bad, rgba(bpy, scene, tmp_path / "without.exr"))


# --------------------------------------------------------------------------------------
# Meshes with a bad vertex.

def _triangulated(bm):
    import bmesh

    bmesh.ops.triangulate(bm, faces=bm.faces[:])  # the same triangles whatever a vertex holds


@pytest.mark.parametrize("value", [np.nan, np.inf, 1e19])
def test_a_mesh_vertex_that_is_not_finite_drops_only_its_triangles(blender, empty_scene, tmp_path, value):
    import bmesh

    bpy, scene = blender, empty_scene
    good_scene(bpy, scene)
    bad = cube(bpy, "Spiky", location=(0, 0, 0.8), edit=_triangulated)
    touching = sum(0 in p.vertices for p in bad.data.polygons)
    positions = np.empty(len(bad.data.vertices) * 3, np.float32)
    bad.data.attributes["position"].data.foreach_get("vector", positions)
    positions[0] = value  # vertex 0's x
    bad.data.attributes["position"].data.foreach_set("vector", positions)
    bad.data.update()
    with_bad = rgba(bpy, scene, tmp_path / "with.exr")
    said_once(report(), "mesh 'Spiky': 1 vertices are not finite or beyond the renderer's limit", "(first: vertex 0)",
              f"the {touching} triangles using them are not rendered")
    assert session().HISTORY[-1]["triangles"] == 12 + 12 - touching
    # The same cube without vertex 0 and its triangles.
    bpy.data.objects.remove(bad)

    def without_vertex_0(bm):
        _triangulated(bm)
        bm.verts.ensure_lookup_table()
        bmesh.ops.delete(bm, geom=[bm.verts[0]], context="VERTS")

    cube(bpy, "Clean", location=(0, 0, 0.8), edit=without_vertex_0)
    without = rgba(bpy, scene, tmp_path / "without.exr")
    assert session().HISTORY[-1]["triangles"] == 12 + 12 - touching
    np.testing.assert_array_equal(with_bad, without)


# --------------------------------------------------------------------------------------
# Lamps.

def lamp(bpy, kind, location, **settings):
    light = bpy.data.lights.new(kind.title(), kind)
    for key, value in settings.items():
        setattr(light, key, value)
    obj = bpy.data.objects.new(kind.title(), light)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = location
    return obj


def lit_scene(bpy, scene):
    """The good scene under one point lamp, in a black world."""
    good_scene(bpy, scene, headlight=False)
    scene.splat_tracer.lighting = "SCENE"
    scene.world = None
    lamp(bpy, "POINT", location=(0, -3, 2), energy=300.0)


@pytest.mark.parametrize("kind", ["POINT", "SPOT", "AREA"])
def test_a_lamp_beyond_the_limit_is_left_out_and_named(blender, empty_scene, tmp_path, kind):
    bpy, scene = blender, empty_scene
    lit_scene(bpy, scene)
    far = lamp(bpy, kind, location=(1e19, 0, 0), energy=1000.0)
    far.name = "Far Away"
    with_bad = rgba(bpy, scene, tmp_path / "with.exr")
    said_once(report(), "light 'Far Away'", "position is beyond the renderer's limit", "not rendered")
    assert session().HISTORY[-1]["lights"] == 1
    far.hide_render = True
    without = rgba(bpy, scene, tmp_path / "without.exr")
    np.testing.assert_array_equal(with_bad, without)
    assert without[..., :3].max() > 0.05  # lit by the good lamp


def test_a_sun_shines_the_same_from_anywhere(blender, empty_scene, tmp_path):
    """A sun's position does not count (Cycles renders one at 1e19 m): nothing to say."""
    bpy, scene = blender, empty_scene
    lit_scene(bpy, scene)
    sun = lamp(bpy, "SUN", location=(0, 0, 0), energy=2.0)
    sun.rotation_euler = (0.3, 0.2, 0.0)
    near = rgba(bpy, scene, tmp_path / "near.exr")
    sun.location = (1e19, 0, 0)
    far = rgba(bpy, scene, tmp_path / "far.exr")
    assert not any("Sun" in line for line in report()) and session().HISTORY[-1]["lights"] == 2
    np.testing.assert_array_equal(near, far)


def test_a_lamp_of_absurd_power_is_clamped_and_named(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    lit_scene(bpy, scene)
    bright = lamp(bpy, "POINT", location=(0, -3, -2), energy=1e30)
    bright.name = "Supernova"
    image = rgba(bpy, scene, tmp_path / "bright.exr")
    said_once(report(), "light 'Supernova'", "a power of 1e+30 is beyond the renderer's limit; clamped to")
    assert session().HISTORY[-1]["lights"] == 2
    assert np.isfinite(image).all()


@pytest.mark.parametrize("kind", ["SPOT", "AREA"])
def test_a_lamp_scaled_to_zero_is_left_out_unless_it_has_no_direction(blender, empty_scene, tmp_path, kind):
    """A spot or area lamp whose Z axis is scaled to 0 has no direction: left out, named. A
    point lamp shines the same whatever its scale."""
    bpy, scene = blender, empty_scene
    lit_scene(bpy, scene)
    flat = lamp(bpy, kind, location=(0, -3, -2), energy=100.0)
    flat.scale = (1.0, 1.0, 0.0)
    point = lamp(bpy, "POINT", location=(1, -3, 0), energy=10.0)
    point.scale = (0.0, 0.0, 0.0)
    with_bad = rgba(bpy, scene, tmp_path / "with.exr")
    said_once(report(), f"light '{flat.name}'", "scaled to 0", "not rendered")
    assert not any(point.name + "'" in line for line in report())
    assert session().HISTORY[-1]["lights"] == 2
    flat.hide_render = True
    np.testing.assert_array_equal(with_bad, rgba(bpy, scene, tmp_path / "without.exr"))


# --------------------------------------------------------------------------------------
# The render border.

# (min x, max x, min y, max y). The first: Blender's result is 1 x 1 pixel at (62, 46) from
# the bottom left, rounding the edges gave 2 x 1 pixels at (62, 47).
@pytest.mark.parametrize("border", [(0.975, 0.999, 0.97, 0.999), (0.99, 1.0, 0.99, 1.0), (0.95, 1.0, 0.96, 1.0),
                                    (0.0, 0.02, 0.0, 0.03), (0.3, 0.7, 0.31, 0.77), (0.0, 1.0, 0.98, 1.0)])
def test_a_border_anywhere_renders_the_pixels_blender_allocates(blender, empty_scene, tmp_path, border):
    """The border's window is Blender's (float32 edges truncated): a border touching the
    top-right pixel used to be a pixel wider than Blender's result, and the frame failed."""
    bpy, scene = blender, empty_scene
    good_scene(bpy, scene)
    scene.render.film_transparent = True
    full = rgba(bpy, scene, tmp_path / "full.exr")
    r = scene.render
    r.use_border, r.use_crop_to_border = True, True
    r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = border
    crop = rgba(bpy, scene, tmp_path / "crop.exr")
    x0, x1, yb0, yb1 = (int(np.float32(getattr(r, f"border_{e}")) * np.float32(size))
                        for e, size in (("min_x", W), ("max_x", W), ("min_y", H), ("max_y", H)))
    assert crop.shape[:2] == (yb1 - yb0, x1 - x0)
    np.testing.assert_array_equal(crop, full[H - yb1:H - yb0, x0:x1])


# --------------------------------------------------------------------------------------
# Splat attributes re-made with another type.

def test_a_retyped_radius_leaves_the_cloud_out_at_render(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    good_scene(bpy, scene)
    bad = cloud("Retyped", location=(0, 0, 0.8))
    attrs = bad.data.attributes
    attrs.remove(attrs["splat_radius"])
    attrs.new("splat_radius", "INT", "POINT")
    with_bad = rgba(bpy, scene, tmp_path / "with.exr")
    said_once(report(), "point cloud 'Retyped': attribute 'splat_radius' must be FLOAT on points, not INT on POINT",
              "not rendered")
    bad.hide_render = True
    np.testing.assert_array_equal(with_bad, rgba(bpy, scene, tmp_path / "without.exr"))


@pytest.mark.parametrize("name, data_type", [("splat_radius", "INT"), ("splat_normal", "FLOAT2"),
                                             ("splat_normal", "FLOAT_COLOR")])
def test_estimate_normals_on_a_retyped_attribute_names_it_and_changes_nothing(blender, empty_scene, name,
                                                                             data_type):
    bpy = blender
    obj = cloud("Retyped")
    attrs = obj.data.attributes
    attrs.remove(attrs[name])
    attrs.new(name, data_type, "POINT")
    before = {a.name: np.array([tuple(getattr(d, k)) if hasattr(getattr(d, k), "__len__") else getattr(d, k)
                                for d in a.data for k in ("vector", "value", "color") if hasattr(d, k)][:50])
              for a in obj.data.attributes if a.name.startswith("splat_")}
    with pytest.raises(RuntimeError) as err, bpy.context.temp_override(selected_objects=[obj]):
        bpy.ops.splat_tracer.estimate_normals(orientation="PROPAGATE")
    expected = "FLOAT" if name == "splat_radius" else "FLOAT_VECTOR"
    assert f"Retyped: attribute '{name}' must be {expected} on points, not {data_type} on POINT" in str(err.value)
    assert "nothing was changed" in str(err.value)
    after = {a.name: np.array([tuple(getattr(d, k)) if hasattr(getattr(d, k), "__len__") else getattr(d, k)
                               for d in a.data for k in ("vector", "value", "color") if hasattr(d, k)][:50])
             for a in obj.data.attributes if a.name.startswith("splat_")}
    assert before.keys() == after.keys()
    for key in before:
        np.testing.assert_array_equal(before[key], after[key])


def test_a_cloud_given_faces_without_its_modifier_is_reported(blender, empty_scene, tmp_path):
    """A face added in Edit Mode to a cloud whose modifier was removed: it renders as the
    mesh Cycles shows, and the splats it leaves out are said."""
    import bmesh

    bpy, scene = blender, empty_scene
    good_scene(bpy, scene)
    obj = cloud("Faced", location=(0, 0, 0.8))
    obj.modifiers.remove(obj.modifiers[0])
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    bm.verts.ensure_lookup_table()
    bm.faces.new(bm.verts[:3])
    bm.to_mesh(obj.data)
    bm.free()
    rgba(bpy, scene, tmp_path / "faced.exr")
    said_once(report(), "object 'Faced' carries splats but evaluates to a mesh with 1 faces",
              "the splats of its 2,000 vertices are not rendered")


# --------------------------------------------------------------------------------------
# Any one bad object among good ones.

# Values one attribute of the bad object gets: non-finite, beyond the core's 1e18, zero.
BAD_VALUES = [np.nan, np.inf, -np.inf, 1e19, -1e30, 3e38, 0.0]
_REFERENCE: dict = {}


@settings(max_examples=40, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(kind=st.sampled_from(["cloud", "mesh"]),
       what=st.sampled_from(["scale", "location", "position", "normal", "radius", "colour", "alpha"]),
       axis=st.integers(0, 2), value=st.sampled_from(BAD_VALUES), row=st.integers(0, 7),
       radius_factor=st.sampled_from([1.0, 100.0]))
def test_one_bad_object_among_good_ones_never_fails_the_frame(blender, tmp_path, kind, what, axis, value, row,
                                                              radius_factor):
    """A cloud or mesh with one NaN, infinite, huge or zero value in one attribute (its
    transform, a vertex, a normal, a radius, a colour) among good objects: the frame renders,
    and the good objects' pixels are the scene's without it. The bad object sits behind the
    camera, so that whatever of it is rendered is not seen; a non-finite value is named."""
    bpy = blender
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "SPLAT_TRACER"
    good_scene(bpy, scene)
    scene.splat_tracer.radius_factor = radius_factor
    if radius_factor not in _REFERENCE:  # the good objects alone
        _REFERENCE[radius_factor] = rgba(bpy, scene, tmp_path / "reference.exr")
    if what == "location" and value == 0.0:
        value = np.nan  # at the origin the object is in view: not a bad value
    behind = (0, -40, 0)  # beyond reach of its discs x the Radius Factor (100): about 8 m
    if kind == "mesh" or what in ("scale", "location"):
        what = what if what in ("scale", "location") else "position"

    def spoil(p, nrm, radii, colours):
        target = {"position": p, "normal": nrm, "colour": colours, "alpha": colours}.get(what)
        if what == "radius":
            radii[row] = value
        elif what == "alpha":
            colours[:, 3] = 0.5
            colours[row, 3] = value
        elif target is not None:
            target[row, axis] = value
        return p, nrm, radii, colours

    if kind == "cloud":
        bad = cloud("Bad", n=400, location=behind, colours=np.ones((400, 4)), edit=spoil)
    else:
        bad = cube(bpy, "Bad", location=behind)
        if what == "position":
            positions = np.empty(len(bad.data.vertices) * 3, np.float32)
            bad.data.attributes["position"].data.foreach_get("vector", positions)
            positions[3 * row + axis] = value
            bad.data.attributes["position"].data.foreach_set("vector", positions)
            bad.data.update()
    if what in ("scale", "location"):
        vector = list(getattr(bad, what))
        vector[axis] = value if what == "scale" else behind[axis] + value
        setattr(bad, what, vector)
    with np.errstate(invalid="ignore", over="ignore"):
        image = rgba(bpy, scene, tmp_path / "bad.exr")
    np.testing.assert_array_equal(image, _REFERENCE[radius_factor])
    if not np.isfinite(value):
        assert any("'Bad'" in line for line in report()), report()


# --------------------------------------------------------------------------------------
# Materials with values that are not finite.

def test_a_material_value_that_is_not_finite_falls_back_to_its_default_and_is_named(blender, empty_scene, tmp_path):
    """Blender keeps a NaN a script or a driver puts in a socket; the material refused the
    frame. Each such value is the contract's default, said once; an emission Blender clamps to
    3.4e38 is clamped to the renderer's limit."""
    bpy, scene = blender, empty_scene
    good_scene(bpy, scene)
    material = bpy.data.materials.new("Broken")
    shader = material.node_tree.nodes["Principled BSDF"]
    shader.inputs["Base Color"].default_value = (math.nan, 0.8, 0.8, 1.0)
    shader.inputs["Roughness"].default_value = math.nan
    bad = cube(bpy, "Painted", location=(0, 0, 0.8))
    bad.data.materials.append(material)
    broken = rgba(bpy, scene, tmp_path / "broken.exr")
    said_once(report(), "material 'Broken': base colour (nan, 0.8, 0.8) is not finite; using (0.8, 0.8, 0.8)")
    said_once(report(), "material 'Broken': roughness nan is not finite; using 0.5")
    shader.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    shader.inputs["Roughness"].default_value = 0.5
    np.testing.assert_array_equal(broken, rgba(bpy, scene, tmp_path / "fixed.exr"))
    shader.inputs["Emission Strength"].default_value = math.inf  # Blender keeps 3.4e38
    shader.inputs["Emission Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    scene.splat_tracer.lighting = "SCENE"
    rgba(bpy, scene, tmp_path / "bright.exr")
    said_once(report(), "material 'Broken': an emission of (3.4e+38, 3.4e+38, 3.4e+38) is beyond the renderer's "
              "limit; clamped to 1e+18")
