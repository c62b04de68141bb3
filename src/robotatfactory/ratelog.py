"""Rate-limited logging for long-running loops: the first message of a kind, then at most one per period,
telling how many were held back. Plain Python, no project import: every layer uses it.

- :class:`LogLimiter` decides (for callers with a logger of their own, e.g. a ROS node's);
- :class:`RateLimitedLog` decides and logs to a :class:`logging.Logger`.
"""
from __future__ import annotations

import logging
import threading
import time


class LogLimiter:
    """At most one message per ``period`` seconds per key (``clock``: wall time by default); thread-safe."""

    def __init__(self, period: float = 5.0, clock=time.monotonic):
        self.period, self.clock = period, clock
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}
        self._lock = threading.Lock()

    def __call__(self, key: str, now: float | None = None) -> str | None:
        """None to stay quiet, else a suffix (possibly empty) to append to the message being logged: how many
        were held back since the last one of this key."""
        now = self.clock() if now is None else now
        with self._lock:
            t = self._last.get(key)
            if t is not None and now - t < self.period:
                self._held[key] = self._held.get(key, 0) + 1
                return None
            self._last[key] = now
            n = self._held.pop(key, 0)
        return f" ({n} more like this in the last {now - t:.0f} s)" if n and t is not None else ""


class RateLimitedLog:
    """``warn(key, msg, *args)``: a warning on ``logger`` through a :class:`LogLimiter`; True when logged."""

    def __init__(self, logger: logging.Logger, period: float = 5.0, clock=time.monotonic):
        self.logger = logger
        self.limit = LogLimiter(period, clock)

    def warn(self, key: str, msg: str, *args) -> bool:
        suffix = self.limit(key)
        if suffix is None:
            return False
        self.logger.warning(msg + suffix, *args)
        return True
