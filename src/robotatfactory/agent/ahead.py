"""Work done ahead, on a thread, while the robot drives: the agent's step stays within its control cycle where a
decision takes longer than one (choosing a picked part's destination plans and times a leg to each free one:
0.85 s in round 1 on this 2-core machine, ``raf bench planning``; in real time the robot stood still with its part
that long after each pick).

One job at a time. Its result is used only where the inputs it was started from are still the inputs (a ``key``
the caller compares), and is waited for there: a paced or a bare run gives the same result however the threads
are scheduled. A job's function reads only its arguments (and constant settings); it must not touch what the
caller's thread changes meanwhile."""
from __future__ import annotations

import threading
from concurrent.futures import Future
from typing import Callable


class Ahead:
    """One job computed ahead (:meth:`start`) and taken where it is needed (:meth:`take`)."""

    def __init__(self, name: str = "raf-ahead"):
        self.name = name
        self._key = None
        self._job: Future | None = None

    def start(self, key, fn: Callable[[], object]) -> None:
        """Run ``fn()`` on a thread of its own for ``key`` (a job not taken is dropped: its thread ends on its
        own, its result unused)."""
        fut: Future = Future()

        def run() -> None:
            try:
                fut.set_result(fn())
            except BaseException as e:  # noqa: BLE001 - handed to the taker: raised where the job is taken
                fut.set_exception(e)

        self._key, self._job = key, fut
        threading.Thread(target=run, name=self.name, daemon=True).start()

    def take(self, same: Callable[[object], bool]):
        """The job's result (waiting for it) when ``same(key)`` holds for the key it was started for, else None;
        the job is gone either way. An exception of the job is raised here."""
        key, job = self._key, self._job
        self.drop()
        if job is None or not same(key):
            return None
        return job.result()

    def drop(self) -> None:
        """Forget the job (its thread ends on its own)."""
        self._key, self._job = None, None
