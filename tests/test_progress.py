"""The batch progress line (experiments/_progress.py): what it says, the time left, drawn only on a terminal."""
from __future__ import annotations

import io

from robotatfactory.experiments._progress import BatchProgress, terminal


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


class Tty(io.StringIO):
    def isatty(self):
        return True


def test_the_line_counts_runs_and_says_the_time_left_at_the_rate_so_far():
    clock = Clock()
    p = BatchProgress(10, jobs=2, enabled=False, clock=clock)
    p.start()
    p.start()
    assert p.line() == "runs 0/10 done, 2 running; 0 s so far, time left unknown yet"
    clock.t += 60.0
    p.finish(True)
    p.finish(False)
    p.start()
    p.start()
    # 2 runs in 60 s: 8 more take 240 s at that rate
    assert p.seconds_left() == 240.0
    assert p.line() == "runs 2/10 done, 2 running, 1 failed; 60 s so far, about 4 min left"
    for _ in range(8):
        p.finish(True)
    assert p.line().startswith("runs 10/10 done, 0 running, 1 failed") and p.line().endswith("done")


def test_a_pool_says_how_many_run():
    p = BatchProgress(5, jobs=2, enabled=False)
    p.finish(None, running=2)
    assert (p.done, p.running) == (0, 2)
    p.finish(True, running=2)
    assert (p.done, p.running) == (1, 2)


def test_drawn_on_a_terminal_only_and_never_under_ci(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    out = Tty()
    p = BatchProgress(3, stream=out)
    assert p.enabled
    p.start()
    p.finish(True)
    p.close()
    text = out.getvalue()
    assert text.startswith("\rruns 0/3 done, 1 running") and "\rruns 1/3 done, 0 running" in text
    assert text.endswith("\n")
    quiet = io.StringIO()  # a pipe or a log file
    q = BatchProgress(3, stream=quiet)
    q.start()
    q.finish(True)
    q.close()
    assert not q.enabled and quiet.getvalue() == ""
    monkeypatch.setenv("CI", "true")
    assert not terminal(Tty())
