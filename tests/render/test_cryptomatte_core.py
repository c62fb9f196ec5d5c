"""Cryptomatte in the core and the render API (render/cryptomatte.py,
native/shade/cryptomatte.h): the ids, the hash and its float conversion, each pixel's
coverage over its samples, sorted, and a frame without the passes unchanged. Blender's side
(the layers, the manifest, the compositor's node, Cycles' layout) is
tests/blender/test_cryptomatte.py."""
from __future__ import annotations

import struct

import numpy as np
import pytest

from splat_tracer.render import cryptomatte
from splat_tracer.render.camera import Camera
from splat_tracer.render.method import Method
from splat_tracer.render.scene import Instance, Mesh, RenderScene, render_arguments
from splat_tracer.render.shading import Material, RenderSettings, World

# Taller than the image: the filter's samples past its top and bottom still meet it.
QUAD = Mesh(np.array([[0, -1, 0], [1, -1, 0], [1, 2, 0], [0, 2, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]))
W = H = 8


def _move(x: float) -> tuple:
    """The quad made 2 wide, from x to x + 2: wider than the image's half."""
    m = np.eye(4)
    m[0, 0], m[0, 3] = 2.0, x
    return tuple(map(tuple, m))


def _scene() -> RenderScene:
    """Two quads side by side, x in [-2, 0] ('Left', material 'Red') and [0, 2] ('Right',
    'Blue', asset 'Rig'), seen from above by an orthographic camera 2 wide: the seam runs
    down the middle of the image, between pixel columns 3 and 4."""
    return RenderScene([
        Instance(QUAD, _move(-2.0), (Material(name="Red"),), name="Left"),
        Instance(QUAD, _move(0.0), (Material(name="Blue"),), name="Right", asset="Rig"),
    ], world=World(colour=(0.0, 0.0, 0.0)))


def _camera(shift: float = 0.0) -> Camera:
    return Camera.look_at((shift, 0.5, 5.0), (shift, 0.5, 0.0), up=(0, 1, 0), ortho_height=1.0, aspect=2.0)


def _render(scene, passes, samples=64, shift=0.0, levels=6, **kw):
    return scene.render(_camera(shift), W, H // 2, RenderSettings(samples=samples, **kw), passes=passes,
                        cryptomatte_levels=levels)


def test_murmur3_reference_values():
    # MurmurHash3_x86_32's published test vectors (seeded and unseeded, every tail length).
    for data, seed, want in [(b"", 0, 0), (b"", 1, 0x514E28B7), (b"abc", 0, 0xB3DD93FA), (b"hello", 0, 0x248BFA47),
                             (b"Hello, world!", 1234, 0xFAF6CDB3),
                             (b"The quick brown fox jumps over the lazy dog", 0x9747B28C, 0x2FA826CD)]:
        assert cryptomatte.murmur3_32(data, seed) == want


def test_float_conversion_makes_every_id_normal():
    bits = lambda f: struct.unpack("<I", struct.pack("<f", f))[0]
    for h in (0x00000000, 0x007FFFFF, 0x7F800000, 0xFF800001, 0x3F800000):
        f = cryptomatte.hash_to_float(h)
        assert np.isfinite(f) and f != 0.0
        exponent = (h >> 23) & 0xFF
        assert bits(f) == (h ^ (1 << 23) if exponent in (0, 255) else h)


def test_metadata_as_cycles_keys_it():
    meta = cryptomatte.metadata("ViewLayer.CryptoObject", ["Cube", "Cube", "Suzanne"])
    key = f"{cryptomatte.name_hash('ViewLayer.CryptoObject'):08x}"[:7]
    assert meta[f"cryptomatte/{key}/name"] == "ViewLayer.CryptoObject"
    assert meta[f"cryptomatte/{key}/hash"] == "MurmurHash3_32"
    assert meta[f"cryptomatte/{key}/conversion"] == "uint32_to_float32"
    assert meta[f"cryptomatte/{key}/manifest"] == (
        '{"Cube":"%08x","Suzanne":"%08x"}' % (cryptomatte.name_hash("Cube"), cryptomatte.name_hash("Suzanne")))


def test_levels_round_up_to_whole_layers():
    assert [cryptomatte.slots_of(n) for n in (2, 3, 6, 16)] == [2, 4, 6, 16]


def test_coverage_per_pixel_sorted():
    scene = _scene()
    # The seam moved a quarter pixel right: the pixels left of it are 3/4 'Left'.
    shift = 0.25 * 2.0 / W
    res = _render(scene, ("CryptoObject", "CryptoMaterial", "CryptoAsset"), samples=256, shift=shift)
    obj, mat, asset = (res.passes[k] for k in cryptomatte.KINDS)
    assert obj.shape == (H // 2, W, 12)  # 6 levels: 6 pairs
    left, right = cryptomatte.name_id("Left"), cryptomatte.name_id("Right")
    # Away from the seam (the Blackman-Harris filter reaches 1.5 pixels): one id, coverage 1.
    np.testing.assert_array_equal(obj[:, :2, 0], left)
    np.testing.assert_allclose(obj[:, :2, 1], 1.0)
    np.testing.assert_array_equal(obj[:, -2:, 0], right)
    np.testing.assert_array_equal(obj[:, :, 4:], 0.0)  # never a third id: the other slots are free
    # Every pixel's coverages add to 1 (the quads fill the image) and are sorted.
    np.testing.assert_allclose(obj[..., 1] + obj[..., 3], 1.0, atol=1e-6)
    assert (obj[..., 1] >= obj[..., 3]).all()
    # The seam's pixel: most of its filter's weight is on 'Left', its second pair is 'Right'.
    seam = obj[:, 3]
    assert (seam[:, 0] == left).all() and (seam[:, 2] == right).all()
    assert (seam[:, 1] > 0.55).all() and (seam[:, 3] > 0.15).all()
    # The material and asset passes carry those names' ids at the same coverage; a missing
    # asset is the object's own name.
    np.testing.assert_array_equal(np.where(obj[..., 0::2] == left, cryptomatte.name_id("Red"),
                                           np.where(obj[..., 0::2] == right, cryptomatte.name_id("Blue"), 0.0)),
                                  mat[..., 0::2])
    np.testing.assert_array_equal(mat[..., 1::2], obj[..., 1::2])
    np.testing.assert_array_equal(np.where(obj[..., 0::2] == right, cryptomatte.name_id("Rig"), obj[..., 0::2]),
                                  asset[..., 0::2])


def test_background_has_no_id():
    scene = RenderScene([Instance(QUAD, _move(0.0), name="Only")])
    res = _render(scene, ("CryptoObject",), samples=16)
    obj = res.passes["CryptoObject"]
    np.testing.assert_array_equal(obj[:, :2], 0.0)  # left half: the world
    np.testing.assert_allclose(obj[:, -2:, 1], 1.0)


def test_an_empty_scene_has_no_ids():
    res = _render(RenderScene([]), cryptomatte.KINDS, samples=2)
    assert all(not res.passes[k].any() for k in cryptomatte.KINDS)


def test_progressive_rendering_gives_the_same_coverage():
    # Adaptive sampling renders in rounds over the whole film (finish() divides by each
    # pixel's own count): with a threshold no pixel meets, the same samples, the same matte.
    scene = _scene()
    a = _render(scene, ("CryptoObject",), samples=32).passes["CryptoObject"]
    b = _render(scene, ("CryptoObject",), samples=32, adaptive_threshold=1e-9,
                adaptive_min_samples=32).passes["CryptoObject"]
    np.testing.assert_allclose(a, b, atol=1e-6)


def test_levels_keep_that_many_pairs():
    res = _render(_scene(), ("CryptoObject",), samples=8, levels=2)
    assert res.passes["CryptoObject"].shape == (H // 2, W, 4)  # one RGBA layer
    assert list(cryptomatte.layers("CryptoObject", res.passes["CryptoObject"])) == ["CryptoObject00"]
    res = _render(_scene(), ("CryptoObject",), samples=8, levels=6)
    assert list(cryptomatte.layers("CryptoObject", res.passes["CryptoObject"])) == [
        "CryptoObject00", "CryptoObject01", "CryptoObject02"]


def test_other_passes_unchanged_by_cryptomatte():
    scene = _scene()
    plain = _render(scene, ("IndexOB",), samples=16)
    with_crypto = _render(scene, ("IndexOB", "CryptoObject", "CryptoAsset"), samples=16)
    for name in ("Combined", "IndexOB"):
        np.testing.assert_array_equal(plain.passes[name], with_crypto.passes[name])


def _core_arguments(scene, ids, kinds=("CryptoObject",)):
    kwargs, buffers = render_arguments(_camera(), W, H // 2, RenderSettings(), Method(), scene.world, kinds,
                                       cryptomatte_ids=ids)
    return kwargs, buffers


def test_core_refuses_bad_ids_and_buffers():
    scene = _scene()
    good = (np.ones((2, 2), np.float32), np.ones(2, np.float32))
    for ids, message in [((np.zeros((2, 2), np.float32), good[1]), "not 0"),
                         ((good[0], np.array([1.0, np.nan], np.float32)), "finite"),
                         ((np.ones((3, 2), np.float32), good[1]), "size"),
                         ((good[0], np.ones(5, np.float32)), "size")]:
        kwargs, _ = _core_arguments(scene, ids)
        with pytest.raises(ValueError, match=message):
            scene._scene.render(**kwargs)
    kwargs, buffers = _core_arguments(scene, good, ("CryptoObject", "CryptoAsset"))
    object_, _, asset, slots, *ids = kwargs["cryptomatte"]
    bad = [((object_, None, asset, 0, *ids), ValueError, "slots"),
           ((object_, None, asset, 17, *ids), ValueError, "slots"),
           ((object_, None, asset), TypeError, "cryptomatte must be"),
           ((object_.astype(np.float64), None, asset, slots, *ids), TypeError, "dtype"),
           ((object_[:, :, :4].copy(), None, asset, slots, *ids), ValueError, "size"),
           ((object_, None, object_, slots, *ids), ValueError, "share memory"),
           ((kwargs["combined"].reshape(H // 2, W, 4)[..., :4].copy(), None, None, 2, *ids), None, None)]
    for arg, error, message in bad:
        if error is None:  # a valid 2-slot buffer: accepted
            scene._scene.render(**{**kwargs, "cryptomatte": arg})
            continue
        with pytest.raises(error, match=message):
            scene._scene.render(**{**kwargs, "cryptomatte": arg})
    with pytest.raises(ValueError, match="share memory"):
        scene._scene.render(**{**kwargs, "cryptomatte": (kwargs["combined"].reshape(H // 2, W, 4), None, None, 2,
                                                          *ids)})
