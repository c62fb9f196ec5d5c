"""The core's light passes, AO and light groups (issue 26): each piece of light goes to
exactly one light pass and to its source's group, nothing of it is computed unless asked for,
and the arguments are checked. (Beside Cycles: tests/blender/test_light_passes.py.)"""
from __future__ import annotations

import numpy as np
import pytest

from splat_tracer.render.camera import Camera
from splat_tracer.render.scene import Instance, Mesh, RenderScene
from splat_tracer.render.shading import LIGHT_PASSES, MAX_LIGHT_GROUPS, Light, Material, RenderSettings, World

W, H = 48, 36
LOBES = ("Diff", "Gloss", "Trans")


def box(centre, half) -> Mesh:
    c = np.asarray(centre, np.float32)
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], np.float32) * half + c
    f = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6], [0, 2, 6],
         [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    return Mesh(v, np.array(f, np.int32))


def stage(world_group="sky", emitter_group="glow") -> RenderScene:
    floor = Mesh(np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], np.float32),
                 np.array([[0, 1, 2], [0, 2, 3]], np.int32))
    return RenderScene(
        [Instance(floor, materials=(Material(base_colour=(0.8, 0.6, 0.4)),)),
         Instance(box((-1, 0, 0.5), 0.5), materials=(Material(metallic=1, roughness=0.2),)),
         Instance(box((1, 0, 0.5), 0.5), materials=(Material(transmission=1, roughness=0.0),)),
         Instance(box((0, 1.5, 0.3), 0.3), materials=(Material(emission=(2, 1, 1)),), light_group=emitter_group)],
        [Light("POINT", power=500, position=(2, -2, 3), light_group="key"),
         Light("POINT", power=300, colour=(0.5, 0.7, 1), position=(-2, -1, 3), light_group="fill")],
        World(colour=(0.1, 0.1, 0.2), light_group=world_group, ao_distance=1.0))


CAM = Camera.look_at((0, -6, 3), (0, 0, 0.5), fov_y=50)
ALL = ("Emit", "Env", "DiffCol", *LIGHT_PASSES[:6], "GlossCol", "TransCol", "AO")
SETTINGS = {"fixed": RenderSettings(samples=8), "adaptive": RenderSettings(samples=16, adaptive=True),
            "clamped": RenderSettings(samples=8, clamp_direct=2.0)}


def recombined(p) -> np.ndarray:
    out = p["Emit"] + p["Env"]
    for lobe in LOBES:
        out = out + (p[lobe + "Dir"] + p[lobe + "Ind"]) * p[lobe + "Col"]
    return out


@pytest.mark.parametrize("mode", sorted(SETTINGS))
def test_light_passes_and_groups_sum_to_combined(mode):
    groups = ("key", "fill", "sky", "glow")
    p = stage().render(CAM, W, H, SETTINGS[mode], passes=ALL, light_groups=groups).passes
    combined = p["Combined"][..., :3]
    assert combined.mean() > 0.1
    # Clamp Direct acts on the lamps met at the first surface, each alone in Combined too.
    assert np.abs(recombined(p) - combined).max() < 1e-5 * combined.max()
    assert np.abs(sum(p["Combined_" + g] for g in groups) - combined).max() < 1e-5 * combined.max()
    for name in ("DiffDir", "DiffInd", "GlossDir", "GlossInd", "TransInd"):
        assert p[name].mean() > 1e-3, name  # every lobe of the scene is lit
    # A group without the world leaves the world's light out: the sum falls short.
    assert (combined - sum(p["Combined_" + g] for g in groups[:2] + groups[3:])).mean() > 0.01
    assert 0.2 < p["AO"].mean() < 1.0


def test_nothing_changes_unless_asked_for():
    """Combined and the other passes are bit-identical with the light passes, AO and groups on."""
    plain = stage().render(CAM, W, H, SETTINGS["fixed"], passes=("Emit", "Env", "DiffCol")).passes
    split = stage().render(CAM, W, H, SETTINGS["fixed"], passes=ALL, light_groups=("key",)).passes
    for name in plain:
        np.testing.assert_array_equal(plain[name], split[name])


def test_a_source_outside_every_group_is_in_none():
    p = stage(world_group="", emitter_group="").render(CAM, W, H, SETTINGS["fixed"],
                                                       light_groups=("key", "fill", "sky")).passes
    assert not p["Combined_sky"].any()
    assert (p["Combined"][..., :3] - p["Combined_key"] - p["Combined_fill"]).mean() > 0.01


def test_bad_light_group_arguments_are_refused():
    s = stage()
    with pytest.raises(ValueError, match="at most"):
        s.render(CAM, 8, 8, light_groups=[f"g{i}" for i in range(MAX_LIGHT_GROUPS + 1)])
    with pytest.raises(TypeError):
        s.render(CAM, 8, 8, light_groups="key")
    with pytest.raises(ValueError, match="ao_distance"):
        World(ao_distance=-1.0)


def test_the_uv_pass_interpolates_the_corner_uvs():
    """A quad seen straight on, its UV map (x, y) / 4 + 0.5: the UV pass is the map at each
    pixel centre, A 1; a cloud's UV is 0; a UV that is not finite is refused."""
    quad = Mesh(np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], np.float32),
                np.array([[0, 1, 2], [0, 2, 3]], np.int32),
                corner_uv=np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], np.float32))
    cam = Camera.look_at((0, 0, 5), (0, 0, 0), up=(0, 1, 0), fov_y=30, aspect=1.0)
    p = RenderScene([Instance(quad)], [Light("SUN", power=1.0)]).render(cam, 16, 16, passes=("UV", "Position"))
    uv, pos = p.passes["UV"], p.passes["Position"]
    hit = pos.any(axis=-1)
    assert hit.all()
    np.testing.assert_allclose(uv[..., 0], pos[..., 0] / 4 + 0.5, atol=1e-5)
    np.testing.assert_allclose(uv[..., 1], pos[..., 1] / 4 + 0.5, atol=1e-5)
    assert (uv[..., 2] == 1).all()
    with pytest.raises(ValueError, match="UV"):
        Mesh(np.zeros((3, 3), np.float32), np.array([[0, 1, 2]], np.int32),
             corner_uv=np.full((1, 3, 2), np.nan, np.float32))


def test_an_environment_world_is_direct_light_in_its_group():
    """An environment-image world, sampled as a light: its light at the first surface is
    Diffuse/Glossy Direct (as Cycles counts world light reaching a surface), all of it in the
    world's group, and the passes still recombine to Combined."""
    sky = np.full((16, 32, 3), 0.05, np.float32)
    sky[12:15, 4:8] = 40.0  # a small bright patch high in the sky: the light it samples
    world = World(colour=(0.1, 0.1, 0.2), light_group="sky", environment=sky)
    lit = RenderScene(_instances(), [], world)
    p = lit.render(CAM, W, H, SETTINGS["fixed"], passes=ALL, light_groups=("sky",)).passes
    combined = p["Combined"][..., :3]
    assert combined.mean() > 0.05
    assert np.abs(recombined(p) - combined).max() < 1e-5 * combined.max()
    np.testing.assert_allclose(p["Combined_sky"], combined, atol=1e-5 * combined.max())
    # Most of the world's light reaches the surfaces directly: Direct well above Indirect.
    assert p["DiffDir"].mean() > 2 * p["DiffInd"].mean() > 0
    assert p["GlossDir"].mean() > 0


def _instances() -> list:
    """stage()'s objects without the emitter: the world alone lights them."""
    floor = Mesh(np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], np.float32),
                 np.array([[0, 1, 2], [0, 2, 3]], np.int32))
    return [Instance(floor, materials=(Material(base_colour=(0.8, 0.6, 0.4)),)),
            Instance(box((-1, 0, 0.5), 0.5), materials=(Material(metallic=1, roughness=0.2),)),
            Instance(box((1, 0, 0.5), 0.5), materials=(Material(transmission=1, roughness=0.0),))]
