"""fuzz/fuzz_core.py must keep rendering: it builds its RenderScene and render arguments with
the add-on's layouts (scene.native_scene, scene.render_arguments, the pack() rows and
SETTINGS_FIELDS), but a change that makes the core refuse every scene it builds would turn
the fuzzer's rendering into refusals, silently. Fixed byte inputs (a deterministic source
for atheris's FuzzedDataProvider) go through the harness's cloud, mesh, scene and render
building; some must render."""
import warnings

import atheris
import numpy as np

from fuzz import fuzz_core
from splat_tracer.render.shading import SETTINGS_FIELDS, RenderSettings

# About one in 30 random inputs renders (the rest are refused, on purpose; the Cryptomatte,
# motion and light-group draws each harness adds refuse more): 256 seeds give a few.
SEEDS = range(256)


def test_fuzz_core_renders_some_scenes():
    rendered = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # hostile values overflow in numpy casts
        for seed in SEEDS:
            fdp = atheris.FuzzedDataProvider(np.random.default_rng(seed).bytes(4096))
            counters = fuzz_core.fuzz_render_scene(fdp, fuzz_core.fuzz_scene(fdp))
            # An accepted render may cast no camera ray when a hostile value the core takes
            # (a lens rotation of -1e308: NaN rays, skipped) spoils them all; it still must
            # finish (the harness asserts it). Only renders that cast rays count below.
            if counters is not None and counters["camera_rays"] > 0:
                rendered.append((seed, counters["lights"], counters["instances"]))
    assert len(rendered) >= 2, f"only {rendered} of seeds {list(SEEDS)} rendered: has a layout drifted?"
    # Lamps and instances too: a drifted row layout refuses only the scenes that have them.
    assert any(lights and instances for _, lights, instances in rendered), rendered


def test_settings_fields_name_every_packed_entry():
    assert len(RenderSettings().pack()) == len(SETTINGS_FIELDS)
    packed = dict(zip(SETTINGS_FIELDS, RenderSettings(time_limit=0.25, mesh_light_strategy="BSDF", samples=3).pack()))
    assert (packed["time_limit"], packed["mesh_light_strategy"], packed["samples"]) == (0.25, 2, 3)
