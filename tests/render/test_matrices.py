"""splat_tracer/util/matrices.py: numpy's answers without BLAS, and no OpenBLAS thread left spinning
by the per-frame matrix work (camera, instances, import axes, the A/B difference)."""
import os
import sys
import threading
import time

import numpy as np
import pytest

from splat_tracer.pointcloud import importer
from splat_tracer.pointcloud.cloud import PointCloud
from splat_tracer.render import difference
from splat_tracer.render.camera import Camera
from splat_tracer.util import matrices

RNG = np.random.default_rng(11)


@pytest.mark.parametrize("n", [2, 3, 4, 6])
def test_inverse_matches_numpy(n):
    for _ in range(100):
        a = RNG.normal(size=(n, n)) * 10.0 ** RNG.integers(-3, 4)
        np.testing.assert_allclose(matrices.inverse(a), np.linalg.inv(a), rtol=1e-9,
                                   atol=1e-9 * np.abs(np.linalg.inv(a)).max())


def test_inverse_of_a_camera_projection_and_an_affine_transform():
    proj = np.array([[2.4, 0, 0, 0], [0, 3.2, 0, 0], [0, 0, -1.0002, -0.020002], [0, 0, -1, 0]])
    np.testing.assert_allclose(matrices.inverse(proj) @ proj, np.eye(4), atol=1e-12)
    m = np.eye(4)
    m[:3, :3] = np.diag([1e-3, 5.0, 2e4]) @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    m[:3, 3] = (512000.25, 5400000.5, 12.0)  # a georeferenced placement
    np.testing.assert_allclose(matrices.inverse(m) @ m, np.eye(4), atol=1e-9)


def test_inverse_refuses_singular_and_non_square_matrices():
    with pytest.raises(np.linalg.LinAlgError):
        matrices.inverse(np.zeros((4, 4)))
    with pytest.raises(np.linalg.LinAlgError):
        matrices.inverse([[1.0, 2.0], [2.0, 4.0]])
    with pytest.raises(np.linalg.LinAlgError):
        matrices.inverse([[np.nan, 0.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match="square"):
        matrices.inverse(np.ones((3, 4)))


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int32])
def test_transform_rows_is_a_float64_product(dtype):
    p = (RNG.normal(size=(5000, 3)) * 100).astype(dtype)
    m = RNG.normal(size=(3, 3))
    out = matrices.transform_rows(p, m)
    assert out.dtype == np.float64 and out.shape == (5000, 3)
    np.testing.assert_allclose(out, p.astype(np.float64) @ m.T, rtol=1e-12, atol=1e-10)
    np.testing.assert_allclose(matrices.transform_rows(p[:, :2], np.ones((4, 2))), p[:, :2].astype(np.float64).sum(axis=1, keepdims=True)
                               * np.ones((1, 4)), rtol=1e-12)
    with pytest.raises(ValueError, match="cannot transform"):
        matrices.transform_rows(p, np.eye(4))


def _other_threads_cpu() -> float:
    """CPU seconds used so far by this process's threads other than the calling one."""
    me = threading.get_native_id()
    total = 0
    for tid in os.listdir("/proc/self/task"):
        if int(tid) == me:
            continue
        try:
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:  # the thread ended meanwhile
            continue
        total += int(fields[11]) + int(fields[12])  # utime, stime
    return total / os.sysconf("SC_CLK_TCK")


def _spin_cost(work, rounds: int = 15) -> float:
    """Other threads' CPU seconds while `work` runs `rounds` times, with the pauses between
    frames a render has (during which OpenBLAS' woken threads would spin)."""
    time.sleep(0.3)  # let threads woken by earlier calls fall asleep
    before = _other_threads_cpu()
    for _ in range(rounds):
        work()
        time.sleep(0.02)
    time.sleep(0.2)
    return _other_threads_cpu() - before


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads per-thread CPU time from /proc")
def test_per_frame_matrix_work_leaves_no_blas_thread_spinning():
    proj = np.array([[2.4, 0, 0, 0], [0, 3.2, 0, 0], [0, 0, -1.0002, -0.020002], [0, 0, -1, 0]])
    # The control: numpy's own inverse of this 4x4 wakes OpenBLAS' pool where it is threaded.
    control = _spin_cost(lambda: np.linalg.inv(proj))
    if control < 0.05:
        pytest.skip(f"numpy's BLAS leaves no thread spinning here ({control:.2f} s): nothing to tell apart")
    world_from_camera = np.eye(4)
    world_from_camera[:3, 3] = (1.0, -2.0, 0.5)
    cloud = PointCloud(RNG.normal(size=(50_000, 3)), RNG.normal(size=(50_000, 3)).astype(np.float32), None, None, 0, 0)
    axes = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # Y up to Z up
    image = RNG.random((120, 160, 3))

    def frame():
        cam = Camera.from_view_projection(proj, world_from_camera, origin=(0.5, 0.5, 0.0))
        cam.rays(64, 48)
        matrices.inverse(world_from_camera)
        importer.transform(cloud, axes, 2.0)
        difference.lab(image)

    ours = _spin_cost(frame)
    assert ours < 0.25 * control, (ours, control)
