"""Reading ``raf sim``'s log in the competition experiment: the final score report, the periodic status
lines and the referee's rule notes.

The report is the referee's (competition/referee.py), the same rule in ``raf sim`` and ``raf referee``: the
points of the parts resting in a correct place at the end (machine stages banked), the time the final score
was reached and held, and the points lost on the way (parts knocked out of a correct place)."""
from __future__ import annotations

import math
import re
import time
from pathlib import Path

_REPORT = re.compile(r"total: (\d+) of (\d+) points(?:[^\n]*?time of the last score ([\d.]+) s)?")
_STATUS = re.compile(r"score (\d+)/(\d+) \([^)]*?(?:last at ([\d.]+) s)?\)")


def parse_sim_report(text: str) -> tuple[int, int, float, bool]:
    """``raf sim``'s score from its log: ``(points, max_points, last_score_s, found)``.

    The final report's ``total: P of M points ...; time of the last score T s`` when it is there (the last
    one), else the last periodic status line's ``score P/M (..., last at T s)`` (a run stopped before its
    report, or a report still unwritten), else ``(0, -1, nan, False)``. T is nan when nothing scored."""
    for rx in (_REPORT, _STATUS):
        m = rx.findall(text)
        if m:
            p, mx, t = m[-1]
            return int(p), int(mx), float(t) if t else math.nan, True
    return 0, -1, math.nan, False


_LOST = re.compile(r"total: \d+ of \d+ points[^\n]*?; (\d+) point\(s\) lost on the way")


def points_lost(text: str) -> int:
    """Points the final report says were taken back during the run (parts knocked out of a correct place);
    0 when it says none (or there is no report)."""
    m = _LOST.findall(text)
    return int(m[-1]) if m else 0


def wait_for_report(log: Path, limit: float = 10.0, poll: float = 0.2) -> bool:
    """Wait up to ``limit`` s until ``log`` holds ``raf sim``'s final report (``total: ... points``): its
    process may have exited with the last lines still on their way to the file. True when found."""
    end = time.monotonic() + limit
    while True:
        try:
            if _REPORT.search(log.read_text(errors="replace")):
                return True
        except OSError:
            pass
        if time.monotonic() >= end:
            return False
        time.sleep(poll)


def notes_of(text: str) -> list[str]:
    """The referee's rule notes in ``raf sim``'s log (each once)."""
    return sorted(set(re.findall(r"note: (.*)", text)))
