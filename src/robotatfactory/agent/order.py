"""The order of the moves left in a round: which part next, and to which slot, so that the last part is placed
soonest (``tasks.plan_order``). Plain Python, no ROS, no I/O but the leg-time cache file.

The task rules (:mod:`.tasks`) choose one move at a time: most machine stages first, then the nearest part, its
slot the one its carrying leg reaches soonest. They do not see what a choice costs later: the empty drive back to
the next part, an outgoing slot under machine B left to the part that reaches it slowest, a machine fed while its
output still holds a finished part (the machine waits). :func:`plan_order` searches every order of the moves left
(branch and bound on the time of the last place) over a table of leg times (:class:`LegTimes`):

* a move takes the empty leg from where the robot stands (the approach pose of the slot it last placed in) to the
  part, ``PICK_S`` to grip and back out, the carrying leg to the destination and ``PLACE_S`` to place and back out;
* the machines run as :mod:`robotatfactory.competition.factory` runs them: a part left at a machine's input is
  processed for the delay once the lane's output is free, and appears there; taking a part from an output starts
  the part waiting at that lane's input. A part still being processed may be the next move's: the robot waits at
  the output for it;
* a blue part from a machine output goes to one of the two outgoing slots nearest the outputs where one is free
  (``near_outputs``: the turns one way only, :meth:`.TaskPolicy.outgoing_near_outputs`).

The search is exact up to ``budget`` moves tried; past it each open branch is finished greedily (the move that
ends soonest), so its CPU is bounded and its answer deterministic.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..competition.parts import PartType
from .state import ZONES, FactoryState, SlotRef
from .tasks import NEAR_OUTPUT_SLOTS, Move, TaskPolicy

#: s to grip a part and back out of its slot (the docking's press and grip; the back-out's ramps)
PICK_S = 1.0
#: s to release a part and back out
PLACE_S = 1.0
#: s of processing assumed before the agent has seen a machine finish (the rules' servers use 5-15 s)
GUESS_DELAY = 10.0
#: moves tried by the exact search before the open branches are finished greedily
NODE_BUDGET = 2000
#: stages of moves still ahead of a part (red: to machine A, then to B, then out)
_STAGES = {PartType.RED: 3, PartType.GREEN: 2, PartType.BLUE: 1}


@dataclass(frozen=True)
class LegTimes:
    """Seconds of the legs between slots: ``empty[(place slot, pick slot)]`` from the approach pose in front of
    the slot the robot placed in to the part's, ``carry[(pick slot, place slot)]`` from the one it backs out to
    with the part to the destination (each leg with its docking approach; inf: no path)."""

    empty: dict
    carry: dict

    @classmethod
    def measure(cls, picks, places, timer: Callable[[SlotRef, SlotRef, bool], float]) -> LegTimes:
        """Every leg between ``picks`` and ``places`` timed by ``timer(source, target, carrying)``."""
        return cls({(a, b): timer(a, b, False) for a in places for b in picks},
                   {(a, b): timer(a, b, True) for a in picks for b in places})

    def to_json(self) -> dict:
        def flat(d):
            return [[a.zone, a.number, b.zone, b.number, None if math.isinf(v) else v] for (a, b), v in d.items()]
        return {"empty": flat(self.empty), "carry": flat(self.carry)}

    @classmethod
    def from_json(cls, data: dict) -> LegTimes:
        def unflat(rows):
            return {(SlotRef(za, int(na)), SlotRef(zb, int(nb))): math.inf if v is None else float(v)
                    for za, na, zb, nb, v in rows}
        return cls(unflat(data["empty"]), unflat(data["carry"]))


@dataclass(frozen=True)
class Plan:
    """The order found: the moves, when the last place ends (s, the clock of ``t``), the moves tried, and whether
    the search was exact (False: past its budget)."""

    moves: tuple[Move, ...]
    finish: float
    nodes: int
    complete: bool


@dataclass(frozen=True)
class _Node:
    t: float                 # s: the robot is free (the last place done)
    at: SlotRef | None       # the slot it last placed in (None: the pose now, ``first_leg``)
    state: FactoryState
    jobs: tuple              # ((input, ready time or None: waits for its output), ...)


def plan_order(policy: TaskPolicy, state: FactoryState, t: float, times: LegTimes, *,
               first_leg: dict[SlotRef, float], delay: float | None = None,
               placed_at: dict[SlotRef, float] | None = None, avoid=frozenset(), near_outputs=(),
               first: SlotRef | None = None, budget: int = NODE_BUDGET) -> Plan | None:
    """The order of the moves left from ``state`` at time ``t`` (s) that places the last part soonest.
    ``first_leg``: seconds of the pick leg from the robot's pose to each part it may take first (a part not in it
    is not taken first); ``delay``: the machines' processing time (None: ``GUESS_DELAY``); ``placed_at``: when the
    part at each machine input was left there; ``avoid``: slots whose parts are not moved; ``near_outputs``: the
    outgoing slots nearest the machine outputs, nearest first (a blue part from an output goes to the first
    ``NEAR_OUTPUT_SLOTS`` of them that are free, if any is); ``first``: the slot of the first move's part, if it
    is given. None when no move can be made now."""
    search = _Search(policy, times, first_leg, GUESS_DELAY if delay is None else float(delay), frozenset(avoid),
                     tuple(near_outputs), budget)
    jobs = []
    for ln in policy.lanes:
        part = state.at(ln.input)
        if part is None or not policy.is_settled(ln.input, part):
            continue
        if state.at(ln.output) is not None:
            jobs.append((ln.input, None))
        else:
            t0 = (placed_at or {}).get(ln.input)
            jobs.append((ln.input, max(t, (t if t0 is None else t0) + search.delay)))
    root = _Node(float(t), None, state, tuple(sorted(jobs)))
    return search.run(root, first)


class _Search:
    def __init__(self, policy, times, first_leg, delay, avoid, near_outputs, budget):
        self.policy, self.times, self.first_leg, self.delay = policy, times, first_leg, delay
        self.avoid, self.near_outputs, self.budget = avoid, near_outputs, budget
        self.nodes = 0
        self.best: tuple[float, tuple] = (math.inf, ())
        known = [v for v in (*times.empty.values(), *times.carry.values()) if math.isfinite(v)]
        self.min_leg = min(known) if known else 0.0

    def run(self, root: _Node, first: SlotRef | None) -> Plan | None:
        children = [c for c in self._children(root) if first is None or c[1].source == first]
        children = [c for c in children if c[1].source in self.first_leg and root.state.at(c[1].source) is not None]
        if not children:
            return None
        for node, move in children:
            self._dive(node, (move,))
        if not math.isfinite(self.best[0]):
            return None
        return Plan(self.best[1], self.best[0], self.nodes, self.nodes <= self.budget)

    # ------------------------------------------------------------------------------------------ the search
    def _dive(self, node: _Node, moves: tuple) -> None:
        self.nodes += 1
        if self._bound(node) >= self.best[0] - 1e-9:
            return
        children = self._children(node)
        if not children:
            if self._finished(node) and node.t < self.best[0]:
                self.best = (node.t, moves)
            return
        if self.nodes > self.budget:  # greedy from here: the move that ends soonest
            children = children[:1]
        for child, move in children:
            self._dive(child, moves + (move,))

    def _bound(self, node: _Node) -> float:
        """A lower bound of the last place's time from ``node``: each move left takes at least two legs and the
        grip and release, one after the other; a part with k moves left (k - 1 machines between them) is placed
        for the last time no sooner than its next move plus, for each machine, the delay and a pick, a carrying
        leg and a place (the empty leg to the output may be driven while the machine works)."""
        moves, chain = 0, node.t
        per_move = 2 * self.min_leg + PICK_S + PLACE_S
        per_stage = self.min_leg + PICK_S + PLACE_S  # after a part comes out
        ready = dict(node.jobs)
        for zone in ZONES:
            for n, part in enumerate(node.state.zone(zone), start=1):
                ref = SlotRef(zone, n)
                if part is None or ref in self.avoid or (zone == "outgoing" and part is PartType.BLUE):
                    continue
                if self.policy.is_settled(ref, part):  # in its machine: out at ``ready`` (or once its output is free)
                    k = _STAGES[part] - 1
                    r = ready.get(ref)
                    start = node.t if r is None else max(node.t, r)
                    chain = max(chain, start + k * per_stage + (k - 1) * self.delay)
                else:
                    k = _STAGES[part]
                    chain = max(chain, node.t + per_move + (k - 1) * (self.delay + per_stage))
                moves += k
        return max(node.t + moves * per_move, chain)

    def _finished(self, node: _Node) -> bool:
        """Every part settled in its final place (blue in outgoing) or avoided."""
        for zone in ZONES:
            for n, part in enumerate(node.state.zone(zone), start=1):
                ref = SlotRef(zone, n)
                if part is not None and ref not in self.avoid and not (zone == "outgoing" and part is PartType.BLUE):
                    return False
        return True

    def _children(self, node: _Node) -> list[tuple[_Node, Move]]:
        """Every move from ``node`` (the parts there now and those the machines will give), with the node after it,
        soonest first."""
        out = []
        ready = dict(node.jobs)
        parts = []
        for zone in ZONES:
            for n, part in enumerate(node.state.zone(zone), start=1):
                ref = SlotRef(zone, n)
                if part is None or ref in self.avoid or self.policy.is_settled(ref, part):
                    continue
                parts.append((ref, part, node.t))
        for ln in self.policy.lanes:  # parts still being processed: taken at the output once there
            r = ready.get(ln.input)
            if r is not None and node.state.at(ln.output) is None and ln.output not in self.avoid:
                parts.append((ln.output, node.state.at(ln.input).next(), r, ln.input))
        for source, part, t_ready, *from_input in parts:
            leg = self._empty(node.at, source)
            if not math.isfinite(leg):
                continue
            t_pick = max(node.t + leg, t_ready) + PICK_S
            after = node.state.with_slot(source, None)
            jobs = dict(node.jobs)
            if from_input:  # it comes out of its machine first
                after = after.with_slot(from_input[0], None)
                del jobs[from_input[0]]
            lane = self.policy.lane_of(source)
            if lane is not None and lane.output == source and lane.input in jobs and jobs[lane.input] is None:
                jobs[lane.input] = t_pick + self.delay  # the output is free: the waiting part starts
            for target in self._destinations(after, part, source):
                carry = self.times.carry.get((source, target), math.inf)
                if not math.isfinite(carry):
                    continue
                t_done = t_pick + carry + PLACE_S
                st = after.with_slot(target, part)
                js = dict(jobs)
                tl = self.policy.lane_of(target)
                if tl is not None and tl.input == target and self.policy.is_settled(target, part):
                    js[target] = None if st.at(tl.output) is not None else t_done + self.delay
                st, js = self._run_machines(st, js, t_done)
                out.append((_Node(t_done, target, st, tuple(sorted(js.items()))), Move(part, source, target)))
        out.sort(key=lambda c: (c[0].t, c[1].source, c[1].target))
        return out

    def _run_machines(self, state: FactoryState, jobs: dict, t: float) -> tuple[FactoryState, dict]:
        """Parts finished by ``t`` moved to their outputs (their inputs freed)."""
        for ln in self.policy.lanes:
            r = jobs.get(ln.input)
            if r is not None and r <= t and state.at(ln.output) is None:
                state = state.with_slot(ln.output, state.at(ln.input).next()).with_slot(ln.input, None)
                del jobs[ln.input]
        return state, jobs

    def _destinations(self, state: FactoryState, part: PartType, source: SlotRef) -> list[SlotRef]:
        """The free slots where ``part`` scores (:meth:`.TaskPolicy.destinations`); a blue part from a machine
        output: the first ``NEAR_OUTPUT_SLOTS`` free of ``near_outputs``, if any is."""
        free = self.policy.destinations(state, part)
        if part is PartType.BLUE and self.policy.is_output(source):
            return [d for d in self.near_outputs if d in free][:NEAR_OUTPUT_SLOTS] or free
        return free

    def _empty(self, at: SlotRef | None, source: SlotRef) -> float:
        if at is None:
            return self.first_leg.get(source, math.inf)
        return self.times.empty.get((at, source), math.inf)


# ---------------------------------------------------------------------------------------------- the table's cache
_TABLES: dict[str, LegTimes] = {}


def leg_times(key: str, measure: Callable[[], LegTimes], cache_dir: Path | None = None) -> LegTimes:
    """The table for ``key`` (a digest of everything the legs depend on: :func:`table_key`): from this process's
    memory, else from ``cache_dir`` (default :func:`default_cache_dir`; None there: no file), else ``measure()``
    (written there atomically for the next process)."""
    if key in _TABLES:
        return _TABLES[key]
    folder = cache_dir if cache_dir is not None else default_cache_dir()
    path = folder / f"legtimes-{key}.json" if folder is not None else None
    table = None
    if path is not None and path.is_file():
        try:
            table = LegTimes.from_json(json.loads(path.read_text()))
        except (OSError, ValueError, KeyError, TypeError):
            table = None  # a damaged file: measured again and replaced
    if table is None:
        table = measure()
        if path is not None:
            _write(path, table)
    _TABLES[key] = table
    return table


def default_cache_dir() -> Path | None:
    """``$RAF_CACHE_DIR``, else ``$XDG_CACHE_HOME/robotatfactory``, else ``~/.cache/robotatfactory``;
    ``RAF_CACHE_DIR=off``: none (measured in every process)."""
    env = os.environ.get("RAF_CACHE_DIR")
    if env:
        return None if env.lower() == "off" else Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "robotatfactory"


def table_key(*parts) -> str:
    """A digest of ``parts`` (reprs of the map, the robot, the settings the legs depend on) and of the agent
    package's source (a changed planner or follower times its legs anew)."""
    h = hashlib.sha256(_source_digest().encode())
    for p in parts:
        h.update(repr(p).encode())
        h.update(b"\0")
    return h.hexdigest()[:20]


_SOURCE: list[str] = []


def _source_digest() -> str:
    if not _SOURCE:
        h = hashlib.sha256()
        for f in sorted(Path(__file__).parent.glob("*.py")):
            h.update(f.name.encode())
            h.update(f.read_bytes())
        _SOURCE.append(h.hexdigest())
    return _SOURCE[0]


def _write(path: Path, table: LegTimes) -> None:
    """Write atomically (a temporary file renamed): concurrent processes never read half a table. A cache that
    cannot be written is no error (the table is measured again next time)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
        os.chmod(tmp, 0o644)  # (mkstemp makes it private; it is a cache anyone may read)
        with os.fdopen(fd, "w") as f:
            json.dump(table.to_json(), f)
        os.replace(tmp, path)
    except OSError:
        pass
