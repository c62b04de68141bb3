"""Rate-limited logging for long-running loops: the first message of a kind, then at most one per period."""
from __future__ import annotations

import logging
import threading
import time


class RateLimitedLog:
    """``warn(key, msg)`` logs at most once per ``period`` seconds per key, telling how many were suppressed."""

    def __init__(self, logger: logging.Logger, period: float = 5.0, clock=time.monotonic):
        self._logger = logger
        self._period = period
        self._clock = clock
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}
        self._lock = threading.Lock()

    def warn(self, key: str, msg: str, *args) -> None:
        now = self._clock()
        with self._lock:
            last = self._last.get(key)
            if last is not None and now - last < self._period:
                self._suppressed[key] = self._suppressed.get(key, 0) + 1
                return
            n = self._suppressed.pop(key, 0)
            self._last[key] = now
        if n:
            msg = f"{msg} ({n} similar suppressed)"
        self._logger.warning(msg, *args)
