"""A Sky Texture inside a material is baked into an equirectangular image (render/sky.py
sky_image) and looked up at its direction: the bake's error against the model itself."""
from __future__ import annotations

import math

import numpy as np
import pytest

from splat_tracer.render import nodes, sky


def _lookup(image, directions):
    b = nodes.Builder()
    vector, uv, colour, alpha = b.register(width=3), b.register(width=3), b.register(width=3), b.register()
    b.emit("GLOBAL", vector, nodes.GLOBALS.index("POSITION"))
    b.emit("IMAGE_PROJECT", uv, vector, nodes.IMAGE_PROJECTIONS.index("EQUIRECTANGULAR"))
    b.emit("IMAGE", colour, alpha, uv, b.image(nodes.Image(image)), nodes.INTERPOLATIONS.index("Linear"),
           nodes.EXTENSIONS.index("REPEAT"))
    return nodes.run(b.program(), len(directions), P=directions.astype(np.float32))[:, colour:colour + 3]


@pytest.fixture(scope="module")
def directions():
    d = np.random.default_rng(1).normal(size=(20000, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize("model", [sky.Sky(multiple=True, sun_elevation=math.radians(20), sun_disc=False),
                                   sky.LegacySky("HOSEK_WILKIE", (0.5, 0.3, 0.6), 2.2, 0.3)],
                         ids=["nishita", "hosek_wilkie"])
def test_the_baked_sky_reads_as_the_model(model, directions):
    ref = model.sky(directions)
    error = np.abs(_lookup(sky.sky_image(model), directions) - ref).max(1) / np.maximum(ref.max(1), 1e-6)
    elevation = np.degrees(np.arcsin(directions[:, 2]))
    above, below = elevation > 2, elevation < -2
    # Measured at 1024 x 512: the sky above 2 degrees within 0.12 % (Nishita) / 0.02 % (Hosek-
    # Wilkie), below -2 degrees within 0.7 %; the horizon's band, where the table turns
    # sharply, is within 40 % at a pixel (its mean 2 %).
    assert error[above].max() < 0.003, error[above].max()
    assert error[below].max() < 0.01, error[below].max()
    assert error[~above & ~below].mean() < 0.05, error[~above & ~below].mean()
    # A bake 8x coarser is off by far more above the horizon.
    coarse = np.abs(_lookup(sky.sky_image(model, 128), directions) - ref).max(1) / np.maximum(ref.max(1), 1e-6)
    assert coarse[above].max() > 3 * error[above].max()
