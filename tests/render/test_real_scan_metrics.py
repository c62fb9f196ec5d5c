"""The real-scan benchmark's image scores (benchmarks/real_scans.py) on tiny images whose
answers are known; the benchmark's scans themselves are never needed here."""
from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks import real_scans


def test_pinholes_are_small_gaps_enclosed_by_the_covered_area():
    covered = np.zeros((12, 12), bool)
    covered[1:11, 1:11] = True
    covered[3, 3] = False            # a one-pixel hole
    covered[6, 3:6] = False          # a 3-pixel slit
    covered[1:11, 8] = False         # a column gap reaching the background: not enclosed
    covered[8, 2] = covered[9, 3] = False  # two one-pixel holes touching only at a corner: two holes
    holes = real_scans.pinholes(covered)
    expected = np.zeros_like(covered)
    expected[3, 3] = expected[8, 2] = expected[9, 3] = True
    expected[6, 3:6] = True
    np.testing.assert_array_equal(holes, expected)
    assert real_scans.pinhole_share(covered) == pytest.approx(6 / (covered.sum() + 6))


def test_an_enclosed_gap_larger_than_the_limit_is_not_a_pinhole():
    covered = np.ones((9, 12), bool)
    covered[3:6, 3:7] = False  # 12 pixels enclosed: more than PINHOLE_PIXELS (9)
    assert real_scans.PINHOLE_PIXELS == 9
    assert not real_scans.pinholes(covered).any()
    assert real_scans.pinholes(covered, max_pixels=12).sum() == 12
    assert not real_scans.pinholes(np.zeros((5, 5), bool)).any()
    assert not real_scans.pinholes(np.ones((5, 5), bool)).any()
    assert math.isnan(real_scans.pinhole_share(np.zeros((5, 5), bool)))


def test_background_around_an_object_is_not_a_pinhole():
    covered = np.zeros((10, 10), bool)
    covered[3:7, 3:7] = True
    assert not real_scans.pinholes(covered).any()
    assert real_scans.pinhole_share(covered) == 0.0


def test_facing_away_share_counts_covered_pixels_whose_normal_points_along_the_ray():
    directions = np.zeros((2, 3, 3))
    directions[..., 2] = -1.0                      # every ray looks down -z
    normal = np.zeros((2, 3, 3))
    normal[..., 2] = 1.0                           # faces the camera
    normal[0, 0] = (0.0, 0.0, -1.0)                # faces away
    normal[0, 1] = (0.0, 0.6, -0.8)                # away, obliquely
    normal[1, 2] = (0.0, 0.0, -1.0)                # away, but not covered
    covered = np.ones((2, 3), bool)
    covered[1, 2] = False
    assert real_scans.facing_away_share(covered, normal, directions) == pytest.approx(2 / 5)
    assert math.isnan(real_scans.facing_away_share(np.zeros((2, 3), bool), normal, directions))


def test_near_black_share_compares_with_a_facing_surface_at_the_same_distance():
    calibration = 2.0                              # a facing surface at distance 1
    distance = np.array([[1.0, 2.0, 4.0, 1.0]])
    # a facing surface at 2 and 4 receives 1/4 and 1/16 of the light at 1
    luminance = np.array([[2.0, 2.0 / 4 * 0.04, 2.0 / 16 * 0.06, 0.0]])
    shade = real_scans.relative_shade(luminance, distance, calibration)
    np.testing.assert_allclose(shade, [[1.0, 0.04, 0.06, 0.0]])
    covered = np.array([[True, True, True, False]])
    # 0.04 is below NEAR_BLACK (0.05), 0.06 above; the uncovered black pixel does not count
    assert real_scans.near_black_share(covered, shade) == pytest.approx(1 / 3)
    assert real_scans.near_black_share(covered, shade, threshold=0.07) == pytest.approx(2 / 3)


def test_the_pose_of_bun045_is_a_rotation_and_the_cache_is_overridable(monkeypatch, tmp_path):
    r = real_scans.bun045_rotation()
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-6)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-6)
    monkeypatch.setenv(real_scans.CACHE_ENV, str(tmp_path))
    assert real_scans.cache_dir() == tmp_path
    assert real_scans.cache_dir(str(tmp_path / "flag")) == tmp_path / "flag"
    monkeypatch.delenv(real_scans.CACHE_ENV)
    assert real_scans.cache_dir() == real_scans.DEFAULT_CACHE


def test_an_empty_cache_is_skipped_naming_where_each_scan_comes_from(tmp_path, capsys):
    assert real_scans.main(["--quick", "--scans", str(tmp_path), "--output", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "bun000.ply: github.com/Minisal/ICP commit ceb04586e8eebd5e1d884237b9e6f95d92e3ecc8, data/bun000.ply" in out
    assert "https://raw.githubusercontent.com/Minisal/ICP/ceb04586e8eebd5e1d884237b9e6f95d92e3ecc8/data/bun000.ply" in out
    assert not (tmp_path / "out").exists()
