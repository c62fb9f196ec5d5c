"""Progress and cancellation of long work (import, normal estimation), without Blender.

The work functions take `progress`: a callable (fraction in 0..1, message) called between
chunks of work. It may raise `Cancelled` to stop the work there; the work functions create
nothing outside their own arrays, so a cancelled import leaves nothing behind. `scaled`
maps a step's own 0..1 onto its share of the whole; `Job` runs a function on a worker
thread (numpy, the core's neighbour search and graph functions, and the file readers
release the GIL in their loops) so that Blender's main thread stays free to draw and to see
Esc.
"""
from __future__ import annotations

import sys
import threading
import time
from typing import Callable, Optional

ProgressFn = Callable[[float, str], None]


class Cancelled(Exception):
    """Raised by a progress callback to stop the work (the user pressed Esc)."""


def nothing(fraction: float, message: str) -> None:
    """A progress callback that shows nothing and never cancels."""


def scaled(progress: Optional[ProgressFn], start: float, end: float, prefix: str = "") -> ProgressFn:
    """`progress` for a step that takes the share start..end of the whole; the step's own
    messages get `prefix`."""
    if progress is None:
        return nothing

    def sub(fraction: float, message: str) -> None:
        progress(start + (end - start) * min(max(fraction, 0.0), 1.0), prefix + message)
    return sub


class Steps:
    """Shares of one progress bar for steps of known relative cost: `steps(name)` is the
    progress callback of that step (steps of weight 0 get none of the bar)."""

    def __init__(self, progress: Optional[ProgressFn], weights: dict):
        self.progress = progress
        total = sum(weights.values()) or 1.0
        self.ranges, at = {}, 0.0
        for name, weight in weights.items():
            self.ranges[name] = (at / total, (at + weight) / total)
            at += weight

    def __call__(self, name: str) -> ProgressFn:
        return scaled(self.progress, *self.ranges[name])

    def span(self, first: str, last: str) -> tuple:
        """(start, end) of the steps first..last together."""
        return self.ranges[first][0], self.ranges[last][1]


def chunks(total: int, size: int, progress: Optional[ProgressFn], message: str):
    """range(0, total, size), reporting the share done before each chunk."""
    for start in range(0, total, size):
        if progress is not None:
            progress(start / max(total, 1), message)
        yield start


class TerminalProgress:
    """Progress as lines on stdout (Blender's background mode has no progress bar): one line
    when the message changes or every `every` seconds, never more often."""

    def __init__(self, label: str, every: float = 2.0, stream=None):
        self.label, self.every, self.stream = label, every, stream or sys.stdout
        self._last_time, self._last_message = -1e9, None

    def __call__(self, fraction: float, message: str) -> None:
        now = time.monotonic()
        if message != self._last_message or now - self._last_time >= self.every:
            self._last_time, self._last_message = now, message
            print(f"{self.label}: {100 * fraction:3.0f} % {message}", file=self.stream, flush=True)


class Job:
    """`work(progress)` on a worker thread. The main thread polls `fraction`/`message`,
    may `cancel()` (the worker stops at its next progress call, raising Cancelled), and
    after `done` reads `result()`, which re-raises the worker's exception. Work inside a call
    that makes no progress call cannot be stopped: the thread is a daemon, so that the main
    thread can stop waiting (`wait(timeout)`) and abandon it."""

    def __init__(self, work: Callable[[ProgressFn], object]):
        self._work = work
        self._cancel = threading.Event()
        self.fraction, self.message = 0.0, "starting"
        self._result = self._error = None
        self._thread = threading.Thread(target=self._run, name="splat_tracer job", daemon=True)

    def _progress(self, fraction: float, message: str) -> None:
        self.fraction, self.message = fraction, message
        if self._cancel.is_set():
            raise Cancelled("cancelled")

    def _run(self) -> None:
        try:
            self._result = self._work(self._progress)
        except BaseException as e:  # handed to the main thread, which reports it
            self._error = e

    def start(self) -> "Job":
        self._thread.start()
        return self

    def cancel(self) -> None:
        self._cancel.set()

    @property
    def done(self) -> bool:
        return not self._thread.is_alive()

    def wait(self, timeout: Optional[float] = None) -> bool:
        self._thread.join(timeout)
        return self.done

    def result(self):
        if not self.done:
            raise RuntimeError("the job is still running")
        if self._error is not None:
            raise self._error
        return self._result
