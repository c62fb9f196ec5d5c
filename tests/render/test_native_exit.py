"""Python exiting while another thread is inside a native call (issue #22): the process must
exit cleanly, never abort. CPython ends a thread that takes the GIL back once finalization has
begun (3.11: pthread_exit, whose unwind through the core's C++ frames aborted the process, 6
runs of 6); the core's atexit hook stops its loops and waits for the calls in flight first
(py_util.h, ExitState).

Each case runs in a fresh interpreter, several times: a daemon thread repeats a long call, the
main thread returns while it is inside it (seen by its progress callback, or by a flag set
around a call with none)."""
from __future__ import annotations

import subprocess
import sys
import textwrap
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
RUNS = 3

# The calls, repeated by the daemon thread: the exit falls inside one, or comes between the
# first poll of one and its end.
SETUP = {
    "splat_render": """
        from splat_tracer.render.camera import Camera
        from splat_tracer.render.splats import SplatCloud
        from geometry import sphere_cloud
        cloud = SplatCloud(*sphere_cloud(20000))
        cam = Camera.look_at((0, 0, 4), (0, 0, 0), (0, 1, 0), 40.0, 1.0)
        def call(progress):
            cloud.render(cam, 1500, 1500, progress=progress, tile_size=8)
    """,
    "scene_render": """
        from splat_tracer.render.camera import Camera
        from splat_tracer.render.scene import Instance, RenderScene
        from splat_tracer.render.shading import Light, RenderSettings, World
        from splat_tracer.render.splats import SplatCloud
        from geometry import sphere_cloud
        scene = RenderScene([Instance(SplatCloud(*sphere_cloud(20000)))], [Light(type="SUN", power=3.0)],
                            World(colour=(0.1, 0.1, 0.1)))
        cam = Camera.look_at((0, 0, 4), (0, 0, 0), (0, 1, 0), 40.0, 1.0)
        # Many samples: one tile takes longer than the test waits (the stop is seen mid-tile).
        settings = RenderSettings(samples=4096)
        def call(progress):
            scene.render(cam, 256, 256, settings, progress=progress, tile_size=64)
    """,
    "spanning_forest": """
        from splat_tracer.pointcloud.graph import spanning_forest
        rng = np.random.default_rng(0)
        n, k = 1_000_000, 8
        nbr = rng.integers(0, n, (n, k)).astype(np.int32)
        weights = rng.random((n, k), dtype=np.float32)
        def call(progress):
            spanning_forest(nbr, weights, progress=None if progress is None else lambda f: progress(0, 0))
    """,
    "point_index": """
        from splat_tracer import _core
        rng = np.random.default_rng(0)
        points = rng.random((50_000, 3), dtype=np.float32)
        index = _core.PointIndex(points)
        rows = np.arange(len(points), dtype=np.int32)
        dist = np.empty((len(points), 16), np.float32)
        ids = np.empty((len(points), 16), np.int32)
        def call(progress):  # no progress callback: the flag below says it is in flight
            index.knn(rows, 16, dist, ids)
    """,
}

CHILD = """
import sys, threading, time
sys.path[:0] = [{root!r}, {support!r}]
import numpy as np
from splat_tracer import _core
{setup}
MODE = {mode!r}
if MODE == "park":
    _core._set_exit_wait(0.0)  # the calls in flight are abandoned: their threads park
# Objects finalization must free: it then lasts long enough (a few tenths of a second) for
# the daemon's next poll to come during it, as a large Blender session's does.
JUNK = [[i] for i in range(1_000_000)]
inside = threading.Event()
def progress(done, total):
    inside.set()
    if MODE == "slow_callback":
        time.sleep(0.3)  # the exit comes while this callback runs
    return False
def work():
    while True:
        inside.set() if NAME == "point_index" else None
        call(progress)
t = threading.Thread(target=work, daemon=True)
t.start()
if not inside.wait(60):
    sys.exit("the call never started")
time.sleep(0.1)
print("exiting", flush=True)
"""


def run_child(name: str, mode: str) -> subprocess.CompletedProcess:
    setup = "NAME = " + repr(name) + "\n" + textwrap.dedent(SETUP[name])
    code = CHILD.format(root=str(ROOT), support=str(ROOT / "tests" / "support"), setup=setup, mode=mode)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("mode", ["wait", "park", "slow_callback"])
@pytest.mark.parametrize("name", sorted(SETUP))
def test_exit_during_a_native_call_never_aborts(name, mode):
    if mode == "slow_callback" and name == "point_index":
        pytest.skip("no progress callback")
    with ThreadPoolExecutor(RUNS) as pool:
        results = list(pool.map(lambda _: run_child(name, mode), range(RUNS)))
    for r in results:
        assert "exiting" in r.stdout, r.stderr
        assert r.returncode == 0, (r.returncode, r.stderr[-2000:])
        for bad in ("FATAL", "Fatal Python error", "core dumped", "terminate called"):
            assert bad not in r.stderr, r.stderr[-2000:]


def test_a_call_after_the_exit_hook_is_refused():
    """Once the hook has run, a new native call raises instead of starting work that could not
    take the GIL back; a call that was stopped raised the same clear error."""
    code = textwrap.dedent(f"""
        import sys
        sys.path[:0] = [{str(ROOT)!r}, {str(ROOT / 'tests' / 'support')!r}]
        import numpy as np
        from splat_tracer import _core
        _core._at_exit()
        try:
            _core.PointIndex(np.zeros((10, 3), np.float32))
        except RuntimeError as e:
            print("refused:", e)
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "refused: Python is exiting" in r.stdout
