"""How soon the Rendered viewport shows something after a change (issue 13's "a coarse
pass within ~100 ms"), measured with the viewport's own session code, headless:

    python -m benchmarks.viewport_latency            (`make bench`: the demo scene, 1280x720 view)
    python -m benchmarks.viewport_latency --quick    (`make bench-quick`: 480x270)

The scene is `make demo`'s (a 31,500-point scan, two sphere clouds, a mesh floor, a sun),
seen from its camera in a view the size of a typical 3D viewport. For each change, the time
from the change to the first (coarse) pass, and to the first full-resolution pass (1 sample;
a large view has an intermediate pass between: viewport.pass_schedule), median of 5 rounds
on this machine's 2 cores:
- the first update (export and every geometry built: opening the viewport);
- a new view (orbiting: nothing exported);
- a setting (epsilon: re-rendered, nothing exported);
- a lamp (its power: exported again, no geometry built);
- one cloud edited (its radius attribute: that cloud rebuilt).
The GPU upload (engine._draw_pixels) is not included: it cannot run headless.
"""
from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

from tools import dev_extension

BUILD = dev_extension.REPO_ROOT / "build" / "viewport_latency"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a 480x270 view, 2 rounds")
    ap.add_argument("--output", default=None, help="also write the table to this Markdown file")
    args = ap.parse_args(argv)
    width, height, rounds = (480, 270, 2) if args.quick else (1280, 720, 5)
    BUILD.mkdir(parents=True, exist_ok=True)
    dev_extension.isolate_user_dirs(str(BUILD / "blender_user"))
    import bpy
    import numpy as np

    dev_extension.enable_from_source(BUILD)
    from tools import demo

    viewport = sys.modules[dev_extension.ADDON_MODULE + ".splat_tracer.blender.viewport"]
    scene, n_splats = demo.build_scene(bpy, 3, width, height)
    scene.cycles.samples = scene.cycles.preview_samples = 16
    bpy.context.view_layer.update()

    def view(turn_deg: float):
        """The scene camera turned about the vertical axis through its target: an orbit."""
        depsgraph = bpy.context.evaluated_depsgraph_get()
        cam = scene.camera.evaluated_get(depsgraph)
        window = cam.calc_matrix_camera(depsgraph, x=width, y=height)
        a = math.radians(turn_deg)
        rot = np.array([[math.cos(a), -math.sin(a), 0, 0], [math.sin(a), math.cos(a), 0, 0], [0, 0, 1, 0],
                        [0, 0, 0, 1]])
        world = rot @ np.array(cam.matrix_world.normalized(), np.float64)
        return viewport.View.of(window, np.linalg.inv(world), width, height)

    def first_passes(session) -> tuple[float, float]:
        """Seconds to the coarse pass and to the full-resolution 1-sample pass."""
        t0 = time.perf_counter()
        session.step()
        coarse = time.perf_counter() - t0
        while session.latest().scale != 1 and session.step():
            pass
        return coarse, time.perf_counter() - t0

    cloud = next(o for o in scene.objects if o.type == "MESH" and "splat_radius" in o.data.attributes)
    lamp = next(o for o in scene.objects if o.type == "LIGHT")
    rows = {name: [] for name in ("first update (export, every build)", "new view (orbit)", "setting (epsilon)",
                                  "lamp power", "one cloud edited")}
    counters = {}
    def measure(session, row: str, changes=None, first: bool = False) -> None:
        """Times the session's update for `changes` (none: only the view changed) and its
        first passes after it, into rows[row]."""
        upd = 0.0
        if changes is not None or first:
            bpy.context.view_layer.update()
            t0 = time.perf_counter()
            session.update(bpy.context.evaluated_depsgraph_get(), changes)
            upd = time.perf_counter() - t0
        c, f = first_passes(session)
        rows[row].append((upd, upd + c, upd + f))

    for r in range(rounds):
        session = viewport.ViewportSession()
        try:
            session.set_view(view(0.0))
            measure(session, "first update (export, every build)", first=True)
            session.set_view(view(5.0 + r))
            measure(session, "new view (orbit)")
            scene.splat_tracer.epsilon = 1.0 + 0.1 * (r + 1)
            measure(session, "setting (epsilon)", viewport.Changes(settings=True))
            lamp.data.energy *= 1.1
            measure(session, "lamp power", viewport.Changes(export=True))
            radius = cloud.data.attributes["splat_radius"].data
            values = np.empty(len(radius), np.float32)
            radius.foreach_get("value", values)
            radius.foreach_set("value", values * 1.01)
            cloud.data.update()
            measure(session, "one cloud edited", viewport.Changes(export=True))
            counters = dict(session.counters)
        finally:
            session.close()
    lines = [f"# Viewport latency: the demo scene ({n_splats:,} splats and a mesh floor, a sun), a {width}x{height} "
             f"view, median of {rounds} rounds",
             f"# session counters of the last round: {counters}", "",
             "| change | update (s) | coarse pass shown (s) | full resolution, 1 sample (s) |", "|---|---:|---:|---:|"]
    for name, values in rows.items():
        u, c, f = (statistics.median(v[k] for v in values) for k in range(3))
        lines.append(f"| {name} | {u:.3f} | {c:.3f} | {f:.3f} |")
    print("\n".join(lines))
    if args.output:
        Path(args.output).write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
