"""The time-to-clean-image benchmark's error metric and search order
(benchmarks/time_to_clean.py) on arrays whose answers are known; no render, no timing."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks import time_to_clean as ttc


def test_identical_images_have_no_error():
    r = np.random.default_rng(1).random((4, 5, 3))
    assert ttc.rel_mse(r, r) == 0.0


def test_a_bright_pixel_counts_its_error_relative_to_its_value():
    r = np.full((2, 3, 3), 2.0)
    a = r + 0.2  # 10 % too bright everywhere
    assert ttc.rel_mse(a, r) == pytest.approx(0.04 / (4.0 + 0.01))
    # Scaling both images by 10 leaves a bright image's relMSE almost unchanged (relative).
    assert ttc.rel_mse(10 * a, 10 * r) == pytest.approx(ttc.rel_mse(a, r), rel=0.01)
    # A plain MSE would grow 100-fold: the metric is not that.
    assert np.mean((10 * a - 10 * r) ** 2) == pytest.approx(100 * np.mean((a - r) ** 2))


def test_a_black_reference_pixel_is_measured_against_the_epsilon():
    r = np.zeros((1, 1, 3))
    a = np.full((1, 1, 3), 0.1)
    assert ttc.EPSILON == 0.01
    assert ttc.rel_mse(a, r) == pytest.approx(0.01 / 0.01)  # finite, not a division by zero


def test_the_mean_runs_over_every_pixel_and_channel_and_alpha_is_left_out():
    r = np.ones((2, 2, 4))
    a = r.copy()
    a[0, 0, 0] = 2.0         # one channel of one pixel: error 1 / (1 + 0.01)
    a[..., 3] = 100.0        # alpha: ignored
    assert ttc.rel_mse(a, r) == pytest.approx((1.0 / 1.01) / 12)


def test_a_one_percent_target_is_what_the_benchmark_uses():
    # 10 % of noise on a unit image is relMSE 1/101: just under the 1 % target.
    r = np.ones((8, 8, 3))
    assert ttc.rel_mse(r * 1.1, r) <= ttc.TARGET < ttc.rel_mse(r * 1.11, r)


def test_images_of_different_sizes_are_refused():
    with pytest.raises(ValueError):
        ttc.rel_mse(np.zeros((2, 2, 3)), np.zeros((2, 3, 3)))


def test_the_search_tries_cheaper_settings_first():
    ladder = list(ttc.sample_ladder(0.01, max_samples=8, steps=2))
    assert ladder == [(1, 0.01), (2, 0.01), (4, 0.01), (8, 0.01), (8, 0.005), (8, 0.0025)]


def test_the_refinement_finds_the_fewest_passing_samples_within_its_steps():
    rendered = []

    def passes(samples):  # an error that falls below the target from 23 samples on
        rendered.append(samples)
        return samples >= 23

    # 16 failed, 32 passed: 24, 20, 22 are tried; 24 is the fewest passing within 3 steps.
    assert ttc.refine(16, 32, passes, steps=3) == 24
    assert rendered == [24, 20, 22]
    rendered.clear()
    assert ttc.refine(16, 32, passes, steps=5) == 23
    rendered.clear()
    assert ttc.refine(1, 2, passes) == 2 and rendered == []  # nothing between: no render


def test_denoiser_named_reads_the_info_line():
    from splat_tracer.blender.export.settings import Denoising

    # The info line as blender/session.py joins it, from the describe() it uses.
    info = f"16 samples; {Denoising('RGB_ALBEDO_NORMAL', 'ACCURATE', 'HIGH').describe()} in 0.05 s"
    assert ttc.denoiser_named(info) == "OpenImageDenoise (CPU)"
    assert ttc.denoiser_named("16 samples") == ""
    assert ttc.denoiser_named("") == ""
