"""Cancelling the import operator's worker (operators/import_cloud.py, _Work): Esc and
Blender's own cancel() never wait on the worker without a bound; a worker that makes no
progress call (a reader inside one library call) is abandoned and its result dropped."""
from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import pytest

from blender_helpers import extension_module

BLOCKED_SECONDS = 30.0  # far longer than any bounded wait: a test that waits for it fails


class _Calls:
    def __init__(self):
        self.calls = []

    def __getattr__(self, name):
        return lambda *args, **kwargs: self.calls.append(name)


def _operator(module, work):
    op = module._Work()
    op.bl_label = "Import Splat Point Cloud"
    op.reports = []
    op.report = lambda kind, message: op.reports.append((kind, message))
    op._job = module.Job(work).start()
    op._timer = object()
    return op, SimpleNamespace(window_manager=_Calls(), workspace=None)


def _uninterruptible(release):
    def work(progress):
        release.wait(BLOCKED_SECONDS)  # no progress call: Cancelled cannot reach it
        return "arrays"
    return work


def _interruptible(progress):
    for _ in range(int(BLOCKED_SECONDS / 0.01)):
        progress(0.5, "reading")
        time.sleep(0.01)
    return "arrays"


@pytest.mark.parametrize("interruptible", [False, True])
def test_cancel_waits_a_bounded_time_then_abandons_the_worker(blender, interruptible):
    module = extension_module("operators.import_cloud")
    release = threading.Event()
    op, context = _operator(module, _interruptible if interruptible else _uninterruptible(release))
    try:
        start = time.monotonic()
        op.cancel(context)
        took = time.monotonic() - start
        assert took < module._CANCEL_WAIT_SECONDS + 1.0
        assert context.window_manager.calls == ["event_timer_remove", "progress_end"]
        if interruptible:  # stopped at its next progress call, well within the wait
            assert op._job.done and took < module._CANCEL_WAIT_SECONDS
            with pytest.raises(module.Cancelled):
                op._job.result()
        else:
            assert not op._job.done  # abandoned, still inside its call
    finally:
        release.set()


@pytest.mark.parametrize("interruptible", [False, True])
def test_esc_ends_the_modal_operator_even_when_the_worker_cannot_stop(blender, interruptible):
    module = extension_module("operators.import_cloud")
    release = threading.Event()
    op, context = _operator(module, _interruptible if interruptible else _uninterruptible(release))
    timer = SimpleNamespace(type="TIMER", value="NOTHING")
    try:
        assert op.modal(context, SimpleNamespace(type="ESC", value="PRESS")) == {"RUNNING_MODAL"}
        deadline = time.monotonic() + module._CANCEL_WAIT_SECONDS + 2.0
        while (state := op.modal(context, timer)) == {"RUNNING_MODAL"}:
            assert time.monotonic() < deadline, "Esc did not end the operator"
            time.sleep(0.05)
        assert state == {"CANCELLED"}
        assert op.reports == [({"WARNING"}, "Import Splat Point Cloud: cancelled, nothing was changed")]
        assert context.window_manager.calls.count("event_timer_remove") == 1
        assert op._job.done == interruptible
    finally:
        release.set()
