"""A batch's progress on one line of a terminal: runs done, running and failed, and the time left.

``raf experiment competition`` plays tens of runs of one to two minutes each; this line says how far it is.
It is drawn only on a terminal (``stream.isatty()``) and never under CI (``CI`` set): a log file or a pipe
gets the experiment's own output and nothing else. Plain Python (no ROS).

    progress = BatchProgress(total=30, jobs=2)
    progress.start()            # a run begins
    progress.finish(ok=True)    # it ends (ok=False: it failed)
    progress.close()            # the batch is over: the line is ended
"""
from __future__ import annotations

import math
import os
import sys
import threading
import time
from typing import Callable, TextIO


def terminal(stream: TextIO) -> bool:
    """Whether ``stream`` is a person's terminal (not a file, a pipe or a CI log)."""
    if os.environ.get("CI", "").strip().lower() not in ("", "0", "false"):
        return False
    try:
        return stream.isatty()
    except (AttributeError, ValueError):
        return False


class BatchProgress:
    """Counts a batch's runs (thread-safe) and redraws one status line on each change."""

    def __init__(self, total: int, jobs: int = 1, stream: TextIO | None = None, enabled: bool | None = None,
                 clock: Callable[[], float] = time.monotonic, what: str = "runs"):
        self.total, self.jobs, self.what = int(total), max(1, int(jobs)), what
        self.stream = sys.stderr if stream is None else stream
        self.enabled = terminal(self.stream) if enabled is None else enabled
        self.clock = clock
        self.t0 = clock()
        self.done = self.failed = self.running = 0
        self._lock = threading.Lock()
        self._width = 0

    def start(self) -> None:
        with self._lock:
            self.running += 1
            self._draw()

    def finish(self, ok: bool | None = True, running: int | None = None) -> None:
        """A run ended (``ok``: whether it succeeded; None: no run ended, only ``running`` changes). ``running``:
        how many run now, where the caller knows better than the count of starts (a process pool's workers)."""
        with self._lock:
            if ok is not None:
                self.running = max(0, self.running - 1)
                self.done += 1
                self.failed += 0 if ok else 1
            if running is not None:
                self.running = running
            self._draw()

    def seconds_left(self) -> float | None:
        """The time left at the rate so far (wall seconds per finished run, ``jobs`` at once); None before the
        first run ends."""
        if self.done == 0:
            return None
        per_run = (self.clock() - self.t0) / self.done
        return per_run * (self.total - self.done)

    def line(self) -> str:
        left = self.seconds_left()
        eta = ("time left unknown yet" if left is None else
               "done" if self.done >= self.total else f"about {_duration(left)} left")
        failed = f", {self.failed} failed" if self.failed else ""
        return (f"{self.what} {self.done}/{self.total} done, {self.running} running{failed}; "
                f"{_duration(self.clock() - self.t0)} so far, {eta}")

    def _draw(self) -> None:
        if not self.enabled:
            return
        text = self.line()
        pad = max(0, self._width - len(text))
        self._width = len(text)
        self.stream.write("\r" + text + " " * pad)
        self.stream.flush()

    def close(self) -> None:
        """End the line (the terminal's next output starts on a line of its own)."""
        if self.enabled and self._width:
            self.stream.write("\n")
            self.stream.flush()


def _duration(s: float) -> str:
    s = max(0.0, float(s))
    if s < 90:
        return f"{math.ceil(s)} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"
