"""The environment light's distribution (native/shade/environment.h), checked against values
computed here independently: its density integrates to 1 over the sphere, the directions it
draws are distributed as that density says, the density is proportional to luminance where
the image is smooth, and the lookup is Cycles' equirectangular orientation."""
import numpy as np
import pytest

from splat_tracer import _core


def _image(seed=1, w=64, h=32):
    """A smooth sky with a small bright sun: the case importance sampling is for."""
    rng = np.random.default_rng(seed)
    img = (0.2 + 0.1 * rng.random((h, w, 3))).astype(np.float32)
    img[20, 10] = (400.0, 350.0, 300.0)  # the sun: one pixel, most of the power
    return img


def _run(img, uniforms, directions):
    n, m = len(uniforms), len(directions)
    out_d = np.zeros((n, 3), np.float32)
    out_pdf = np.zeros(n, np.float32)
    out_pdf_at = np.zeros(m, np.float32)
    out_rad = np.zeros((m, 3), np.float32)
    _core._environment_map(img, np.ascontiguousarray(uniforms, np.float32),
                           np.ascontiguousarray(directions, np.float32), out_d, out_pdf, out_pdf_at, out_rad)
    return out_d, out_pdf, out_pdf_at, out_rad


def _grid(nu=2048, nv=1024):
    """Directions at the centres of a fine (u, v) grid and the solid angle of each cell."""
    u = (np.arange(nu) + 0.5) / nu
    v = (np.arange(nv) + 0.5) / nv
    uu, vv = np.meshgrid(u, v)
    phi, el = (0.5 - uu) * 2 * np.pi, (vv - 0.5) * np.pi
    d = np.stack([np.cos(el) * np.cos(phi), np.cos(el) * np.sin(phi), np.sin(el)], -1).reshape(-1, 3)
    cell = (2 * np.pi / nu) * (np.pi / nv) * np.cos(el).ravel()
    return d, cell


def test_pdf_integrates_to_one():
    d, cell = _grid()
    _, _, pdf_at, _ = _run(_image(), np.zeros((0, 2)), d)
    total = float(np.sum(pdf_at * cell))
    assert abs(total - 1.0) < 2e-3, total


def test_samples_follow_the_pdf():
    img = _image()
    rng = np.random.default_rng(7)
    u = rng.random((200_000, 2)).astype(np.float32)
    u = np.minimum(u, np.float32(1 - 2 ** -24))
    dirs, pdf, pdf_again, _ = _run(img, u, rng.standard_normal((0, 3)))
    assert np.all(pdf > 0)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-5)
    # The density sample() reports is the one pdf() gives at the drawn direction (but for
    # draws on a pixel's edge, which float rounding may put in the neighbour: < 0.1 %).
    _, _, pdf_at, _ = _run(img, np.zeros((0, 2)), dirs)
    assert np.mean(~np.isclose(pdf_at, pdf, rtol=2e-3)) < 1e-3
    # A histogram of the draws over 8 x 4 cells of (u, v) against the integral of the pdf there.
    uu = 0.5 - np.arctan2(dirs[:, 1], dirs[:, 0]) / (2 * np.pi)
    vv = 0.5 + np.arcsin(np.clip(dirs[:, 2], -1, 1)) / np.pi
    counts, _, _ = np.histogram2d(vv, uu, bins=(4, 8), range=((0, 1), (0, 1)))
    d, cell = _grid(512, 256)
    _, _, p, _ = _run(img, np.zeros((0, 2)), d)
    expected = (p * cell).reshape(256, 512).reshape(4, 64, 8, 64).sum(axis=(1, 3)) * len(u)
    sigma = np.sqrt(expected) + 1
    assert np.all(np.abs(counts - expected) < 5 * sigma), (counts, expected)
    # Most draws go to the sun (its 3x3 support holds most of the weighted luminance).
    assert counts.max() > 0.8 * len(u)


def test_lookup_orientation_is_cycles():
    """+x is the image's middle column (u = 0.5), +y a quarter to the left (u = 0.25), up the
    top row: Cycles' direction_to_equirectangular."""
    h, w = 32, 64
    img = np.zeros((h, w, 3), np.float32)
    img[h // 2 - 1: h // 2 + 1, w // 2 - 1: w // 2 + 1] = (1, 0, 0)  # around +x
    img[h // 2 - 1: h // 2 + 1, w // 4 - 1: w // 4 + 1] = (0, 1, 0)  # around +y
    img[-1, :] = (0, 0, 1)  # the zenith row
    _, _, _, rad = _run(img, np.zeros((0, 2)), np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0]], np.float32))
    assert np.allclose(rad, [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]], atol=1e-5)


def test_black_image_is_not_sampled():
    img = np.zeros((8, 16, 3), np.float32)
    _, pdf, pdf_at, _ = _run(img, np.full((4, 2), 0.5), np.array([[0, 0, 1.0]], np.float32))
    assert np.all(pdf == 0) and np.all(pdf_at == 0)


@pytest.mark.parametrize("bad", [np.full((8, 16, 3), np.nan, np.float32), np.full((8, 16, 3), -1, np.float32),
                                 np.zeros((1, 16, 3), np.float32)])
def test_bad_images_are_refused(bad):
    with pytest.raises(ValueError):
        _run(bad, np.zeros((0, 2)), np.zeros((0, 3)))
