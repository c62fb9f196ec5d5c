"""Geometry-derived shader inputs (issue 24) through Blender, side by side with Cycles:
Geometry > Tangent, Parametric, Pointiness, Random Per Island, the Tangent node, the Color
Attribute node's layer, and a Sky Texture inside a material.

Every material is an Emission shader whose colour is the input under test (a vector v as
v / 2 + 1/2), on a mesh seen straight down by an orthographic camera over a black world
(test_node_materials' _setup without its sun: nothing else lights anything), 64x64 px.
Tolerances (measured with bpy 5.0.1; each test also shows that a wrong render fails):
- EXACT_ATOL = 0.02: mean absolute difference per channel for inputs computed as Cycles
  computes them (the remainder is the two renderers' anti-aliasing of the silhouette and of
  facet edges); a wrong render (the tangent turned 90 degrees, the islands' values
  mirrored, the pointiness contrast halved, the paint turned, the sky flipped) is several
  times further. The sky on a ball: mean colour within 2 %, relative mean absolute
  difference within 5 % (measured 0.1-0.2 % and 0.9-1.4 %).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from test_node_materials import _both
from test_node_coordinates import _emission, _said
from test_scene_export import black_world, direct_light_only, mesh_object

EXACT_ATOL = 0.02
SIZE = 64


def _view(bpy, scene, ortho_scale=2.2):
    from blender_helpers import add_camera

    add_camera(bpy, scene, (0, 0, 5), (0, 0, 0), type="ORTHO", ortho_scale=ortho_scale)
    black_world(bpy, scene)
    direct_light_only(scene)
    c = scene.cycles
    c.samples, c.device, c.use_denoising, c.use_adaptive_sampling = 16, "CPU", False, False


def _render(bpy, scene, tmp_path, name):
    import test_node_materials

    size, test_node_materials.SIZE = test_node_materials.SIZE, SIZE
    try:
        return _both(bpy, scene, tmp_path, name)
    finally:
        test_node_materials.SIZE = size


def _as_colour(nodes, links, vector_socket, emission):
    """Emission colour = vector / 2 + 1/2."""
    mad = nodes.new("ShaderNodeVectorMath")
    mad.operation = "MULTIPLY_ADD"
    mad.inputs[1].default_value = (0.5, 0.5, 0.5)
    mad.inputs[2].default_value = (0.5, 0.5, 0.5)
    links.new(vector_socket, mad.inputs[0])
    links.new(mad.outputs["Vector"], emission.inputs["Color"])


def _mad(a, b):
    return float(np.abs(a - b).mean())


def _ball(bpy, material, rotation=(0.4, 0.3, 0.6), scale=(1.0, 0.8, 1.0)):
    import bmesh

    def build(bm):
        bm.loops.layers.uv.new("UVMap")
        bmesh.ops.create_uvsphere(bm, u_segments=48, v_segments=24, radius=1.0, calc_uvs=True)

    obj = mesh_object(bpy, "Ball", build, (0, 0, 0), [material], smooth=True)
    obj.rotation_euler, obj.scale = rotation, scale
    # A second map, not the active render one: the first's u and v swapped.
    uv = np.empty(len(obj.data.loops) * 2, np.float32)
    obj.data.uv_layers["UVMap"].uv.foreach_get("vector", uv)
    turned = obj.data.uv_layers.new(name="Turned", do_init=False)
    turned.uv.foreach_set("vector", uv.reshape(-1, 2)[:, ::-1].ravel())
    obj.data.uv_layers["UVMap"].active_render = True
    return obj


@pytest.mark.parametrize("kind", ["geometry", "radial_x", "radial_y", "uv_map", "uv_named", "parametric"])
def test_tangents_and_parametric_match_cycles(blender, empty_scene, tmp_path, kind):
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, f"Tangent_{kind}")
    if kind in ("geometry", "parametric"):
        geometry = nodes.new("ShaderNodeNewGeometry")
        _as_colour(nodes, links, geometry.outputs["Tangent" if kind == "geometry" else "Parametric"], emission)
    else:
        tangent = nodes.new("ShaderNodeTangent")
        if kind in ("uv_map", "uv_named"):
            tangent.direction_type = "UV_MAP"
            tangent.uv_map = "Turned" if kind == "uv_named" else ""
        else:
            tangent.direction_type, tangent.axis = "RADIAL", kind[-1].upper()
        _as_colour(nodes, links, tangent.outputs["Tangent"], emission)
    _ball(bpy, m)
    _view(bpy, scene)
    ours, theirs, report = _render(bpy, scene, tmp_path, f"tangent_{kind}")
    d = _mad(ours, theirs)
    print(kind, "mean abs difference", d)
    assert not _said(report, m.name), report
    # Cycles interpolates MikkTSpace tangents per vertex; here the UV map's tangent is the
    # triangle's: on this 48 x 24 ball the facets' steps show.
    assert d <= (0.03 if kind.startswith("uv") else EXACT_ATOL), d
    wrong = ours[..., [1, 0, 2]] if kind != "parametric" else ours[..., [1, 2, 0]]
    assert _mad(wrong, theirs) > 3 * EXACT_ATOL, "a tangent turned (channels swapped) must fail"


def _islands(bm, count=5):
    import bmesh

    for k in range(count):
        geom = bmesh.ops.create_cube(bm, size=0.35)["verts"]
        bmesh.ops.translate(bm, verts=geom, vec=(-0.8 + 0.4 * k, 0.3 * ((-1) ** k), 0))


def test_random_per_island_matches_cycles(blender, empty_scene, tmp_path):
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "Islands")
    geometry = nodes.new("ShaderNodeNewGeometry")
    links.new(geometry.outputs["Random Per Island"], emission.inputs["Color"])
    mesh_object(bpy, "Islands", _islands, (0, 0, 0), [m])
    _view(bpy, scene)
    ours, theirs, report = _render(bpy, scene, tmp_path, "islands")
    d = _mad(ours, theirs)
    print("random per island mean abs difference", d)
    assert not _said(report, m.name), report
    assert d <= EXACT_ATOL, d
    # Each island's value, read at its centre, as Cycles gives it (a hash: any other
    # representative or hash would be off by far more).
    for k in range(5):
        x, y = -0.8 + 0.4 * k, 0.3 * ((-1) ** k)
        col, row = int((x / 2.2 + 0.5) * SIZE), int((0.5 - y / 2.2) * SIZE)
        np.testing.assert_allclose(ours[row, col], theirs[row, col], atol=2e-3)
    inside = theirs.sum(-1) > 0
    assert _mad(np.flip(ours, axis=1)[inside], theirs[inside]) > 3 * EXACT_ATOL, "islands' values swapped must fail"


def test_pointiness_matches_cycles(blender, empty_scene, tmp_path):
    import bmesh

    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "Pointy")
    geometry = nodes.new("ShaderNodeNewGeometry")
    # Pointiness is near 0.5 on a smooth surface: stretched so that its variation shows.
    ramp = nodes.new("ShaderNodeMapRange")
    ramp.inputs["From Min"].default_value, ramp.inputs["From Max"].default_value = 0.4, 0.6
    links.new(geometry.outputs["Pointiness"], ramp.inputs["Value"])
    links.new(ramp.outputs["Result"], emission.inputs["Color"])
    obj = mesh_object(bpy, "Monkey", lambda bm: bmesh.ops.create_monkey(bm), (0, 0, 0), [m], smooth=True)
    obj.rotation_euler = (math.radians(-60), 0, 0)
    _view(bpy, scene, ortho_scale=2.4)
    ours, theirs, report = _render(bpy, scene, tmp_path, "pointiness")
    d = _mad(ours, theirs)
    print("pointiness mean abs difference", d, "correlation", np.corrcoef(ours.ravel(), theirs.ravel())[0, 1])
    assert not _said(report, m.name), report
    assert d <= EXACT_ATOL, d
    assert np.corrcoef(ours.ravel(), theirs.ravel())[0, 1] >= 0.98
    inside = theirs.sum(-1) > 0
    wrong = np.clip((0.5 + (ours - 0.5) * 0.5), 0, 1)  # half the curvature (e.g. the blur done twice)
    assert _mad(wrong[inside], theirs[inside]) > 2 * EXACT_ATOL, _mad(wrong[inside], theirs[inside])


@pytest.mark.parametrize("layer", ["Paint", "Color"])  # "Color": a name that also means a scan's colours
def test_colour_attribute_layer_matches_cycles(blender, empty_scene, tmp_path, layer):
    import bmesh

    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "Painted")
    node = nodes.new("ShaderNodeVertexColor")
    node.layer_name = layer
    mix = nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.inputs["B"].default_value = (0.0, 0.0, 1.0, 1.0)
    links.new(node.outputs["Alpha"], mix.inputs["Factor"])
    links.new(node.outputs["Color"], mix.inputs["A"])
    links.new(mix.outputs["Result"], emission.inputs["Color"])

    def build(bm):
        bmesh.ops.create_grid(bm, x_segments=4, y_segments=4, size=1.0)

    obj = mesh_object(bpy, "Painted", build, (0, 0, 0), [m])
    mesh = obj.data
    # Two layers: the one named (byte colours on corners, alpha varying) and another (float
    # colours on points, the active one) that must not be read.
    paint = mesh.color_attributes.new(layer, "BYTE_COLOR", "CORNER")
    other = mesh.color_attributes.new("Other", "FLOAT_COLOR", "POINT")
    rng = np.random.default_rng(3)
    paint.data.foreach_set("color", rng.uniform(0, 1, (len(mesh.loops), 4)).astype(np.float32).ravel())
    other.data.foreach_set("color", np.ones(len(mesh.vertices) * 4, np.float32))
    mesh.color_attributes.active_color = other
    _view(bpy, scene)
    ours, theirs, report = _render(bpy, scene, tmp_path, f"colour_layer_{layer}")
    d = _mad(ours, theirs)
    print("colour attribute mean abs difference", d)
    assert not _said(report, m.name), report
    assert d <= EXACT_ATOL, d
    assert _mad(np.rot90(ours), theirs) > 3 * EXACT_ATOL, "the paint turned must fail"


@pytest.mark.parametrize("sky_type, linked, sun", [("MULTIPLE_SCATTERING", True, 0), ("HOSEK_WILKIE", True, 0),
                                                   ("MULTIPLE_SCATTERING", False, 0), ("MULTIPLE_SCATTERING", True, 8)])
def test_sky_texture_in_a_material_matches_cycles(blender, empty_scene, tmp_path, sky_type, linked, sun):
    """A Sky Texture on a ball by its normal (a mirror ball of the sky), without the sun disc;
    unlinked, by the generated coordinates (Cycles' default for a texture). With a sun disc
    (8 degrees) Blender makes the Vector unavailable: the link is ignored, the generated
    coordinates read, in both; the disc is not drawn here (said), and none of it is in
    Cycles' view of this ball either."""
    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "SkyBall")
    sky = nodes.new("ShaderNodeTexSky")
    sky.sky_type = sky_type
    if sky_type == "MULTIPLE_SCATTERING":
        sky.sun_disc, sky.sun_elevation, sky.sun_rotation = sun > 0, math.radians(25), math.radians(40)
        sky.sun_size = math.radians(max(sun, 0.545))
    else:
        sky.sun_direction = (0.5, 0.3, 0.6)
    coords = nodes.new("ShaderNodeTexCoord")
    if linked:
        links.new(coords.outputs["Normal"], next(s for s in sky.inputs if s.name == "Vector"))
    links.new(sky.outputs["Color"], emission.inputs["Color"])
    obj = _ball(bpy, m, rotation=(math.radians(-70), 0, 0), scale=(1, 1, 1))
    obj.data.polygons.foreach_set("use_smooth", [True] * len(obj.data.polygons))
    _view(bpy, scene)
    ours, theirs, report = _render(bpy, scene, tmp_path, f"sky_{sky_type}_{linked}_{sun}")
    inside = theirs.sum(-1) > 0
    rel = float(np.abs(ours[inside] - theirs[inside]).mean() / theirs[inside].mean())
    print(sky_type, "relative mean abs difference", rel, "means", ours[inside].mean(0), theirs[inside].mean(0))
    said = _said(report, m.name)
    assert said == ([f"material '{m.name}': the Sky Texture's sun disc is not drawn in a material (the sky is)"]
                    if sun else []), report
    np.testing.assert_allclose(ours[inside].mean(0), theirs[inside].mean(0), rtol=0.02)
    assert rel <= 0.05, rel
    assert float(np.abs(np.flip(ours, 0)[inside] - theirs[inside]).mean() / theirs[inside].mean()) > 0.1


@pytest.mark.parametrize("output", ["Pointiness", "Random Per Island", "Parametric", "Tangent"])
def test_on_a_point_cloud(blender, empty_scene, tmp_path, output):
    """A scan (the importer's points, which Cycles renders as spheres) with the Geometry
    output as its emitted colour: Pointiness and Random Per Island are 0 on points in both
    (Cycles derives them for meshes only), Parametric (1, 0, 0) (a point's u = v = 0).
    Cycles' Tangent on a point is its zero dPdu normalised, not a number (black); here the
    radial tangent as on a mesh (a unit vector perpendicular to the splat's normal)."""
    from test_node_materials import _flat_cloud

    bpy, scene = blender, empty_scene
    m, nodes, links, emission = _emission(bpy, "OnPoints")
    geometry = nodes.new("ShaderNodeNewGeometry")
    if output in ("Parametric", "Tangent"):
        _as_colour(nodes, links, geometry.outputs[output], emission)
    else:
        links.new(geometry.outputs[output], emission.inputs["Color"])
    _flat_cloud(bpy, m)
    _view(bpy, scene)
    ours, theirs, report = _render(bpy, scene, tmp_path, f"points_{output}")
    centre = slice(SIZE // 4, 3 * SIZE // 4)
    mine, cycles = ours[centre, centre].reshape(-1, 3), theirs[centre, centre].reshape(-1, 3)
    print(output, "ours", mine.mean(0), mine.std(0), "Cycles", cycles.mean(0), cycles.std(0))
    assert not _said(report, m.name), report
    if output in ("Pointiness", "Random Per Island"):
        assert np.abs(mine).max() == 0 and np.abs(cycles).max() < 1e-6
    elif output == "Parametric":
        np.testing.assert_allclose(mine, cycles, atol=1e-3)
        np.testing.assert_allclose(cycles.mean(0), [1.0, 0.5, 0.5], atol=1e-3)
    else:
        assert np.abs(cycles).max() < 1e-6  # Cycles: not a number
        tangent = mine * 2 - 1  # the splats face +Z: a unit vector in the plane
        # (but at the middle, where a radial direction has none: 0 there, as Cycles' safe 0)
        assert np.percentile(np.abs(np.linalg.norm(tangent, axis=1) - 1.0), 98) < 0.02
        assert np.abs(tangent[:, 2]).max() < 0.02
