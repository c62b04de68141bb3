"""The order of the moves (agent/order.py, ``tasks.plan_order``): the search against a brute force over every order
and slot, the machines' timing (a machine waits for its output), the rules it keeps (near outputs, the first part,
avoided parts), its budget, the leg-time table and its cache, and a bare round driving the order it chose."""
from __future__ import annotations

import itertools
import json
import math

import pytest
from hypothesis import assume, given, settings, strategies as st

from robotatfactory.agent import order as order_mod
from robotatfactory.agent.order import PICK_S, PLACE_S, LegTimes, leg_times, plan_order
from robotatfactory.agent.state import ZONES, FactoryState, SlotRef
from robotatfactory.agent.tasks import MACHINE_OF, Move, TaskPolicy
from robotatfactory.competition.parts import PartType
from robotatfactory.field import load_field

FIELD = load_field()
POLICY = TaskPolicy.for_field(FIELD)
LANES = POLICY.lanes
OUTPUTS = [ln.output for ln in LANES]
INPUTS = [ln.input for ln in LANES]
PICKS = [SlotRef("incoming", n) for n in range(1, 5)] + OUTPUTS
PLACES = [SlotRef("outgoing", n) for n in range(1, 5)] + INPUTS
OUT = [SlotRef("outgoing", n) for n in range(1, 5)]


def uniform(seconds: float) -> LegTimes:
    return LegTimes.measure(PICKS, PLACES, lambda a, b, c: seconds)


def first_legs(state: FactoryState, seconds: float) -> dict:
    return {SlotRef(z, n): seconds for z in ZONES for n in range(1, 5) if state.at(SlotRef(z, n)) is not None}


# ---------------------------------------------------------------------------------------------- an independent model
def simulate(moves, state, t, times, first_leg, delay, near=(), final=True):
    """The time the last of ``moves`` is placed, by the rules in order.py's docstring, written apart from its search
    (None: a move that cannot be made, or with ``final`` a part not in its last place at the end). A machine
    processes a part left at its input for ``delay`` once its output is empty; a part is picked once it is at its
    slot (the robot waits at an output for it); a slot must be free when the robot sets off with the part."""
    slots = {SlotRef(z, n): state.at(SlotRef(z, n)) for z in ZONES for n in range(1, 5)}
    lane_in = {ln.input: ln for ln in LANES}
    lane_out = {ln.output: ln for ln in LANES}
    ready = {}  # input -> time its part comes out, or None: waiting for the output
    for ln in LANES:
        p = slots[ln.input]
        if p is not None and MACHINE_OF.get(p) == ln.machine:
            ready[ln.input] = None if slots[ln.output] is not None else t + delay  # (left there now)
    at = None
    for k, m in enumerate(moves):
        leg = first_leg.get(m.source, math.inf) if at is None else times.empty.get((at, m.source), math.inf)
        appears = t
        if slots[m.source] is None:  # a part still in its machine may be waited for (not by the first move)
            ln = lane_out.get(m.source)
            if k == 0 or ln is None or ready.get(ln.input) is None:
                return None
            appears = ready.pop(ln.input)
            slots[m.source], slots[ln.input] = slots[ln.input].next(), None
        if slots[m.source] is not m.part or slots[m.target] is not None or not math.isfinite(leg):
            return None
        if m.part is PartType.BLUE and m.source in lane_out and near:
            allowed = [d for d in near if slots[d] is None][:2]
            if allowed and m.target not in allowed:
                return None
        if m.part is not PartType.BLUE and m.target not in lane_in:
            return None
        t_pick = max(t + leg, appears) + PICK_S
        slots[m.source] = None
        ln = lane_out.get(m.source)
        if ln is not None and ln.input in ready and ready[ln.input] is None:
            ready[ln.input] = t_pick + delay
        t = t_pick + times.carry[(m.source, m.target)] + PLACE_S
        slots[m.target] = m.part
        ln = lane_in.get(m.target)
        if ln is not None:
            ready[m.target] = None if slots[ln.output] is not None else t + delay
        for inp, r in list(ready.items()):  # the machines up to now
            ln = lane_in[inp]
            if r is not None and r <= t and slots[ln.output] is None:
                slots[ln.output], slots[inp] = slots[inp].next(), None
                del ready[inp]
        at = m.target
    if final and not all(p is None or (s.zone == "outgoing" and p is PartType.BLUE) for s, p in slots.items()):
        return None
    return t


def brute_force(state, t, times, first_leg, delay, near=()):
    """The soonest finish over every sequence of moves (each part through its machines, every slot), by
    :func:`simulate`."""
    every = set()
    for z in ZONES:
        for n in range(1, 5):
            p = state.at(SlotRef(z, n))
            if p is None:
                continue
            routes = [(q, o) for o in OUTPUTS for q in (PartType.GREEN, PartType.BLUE)]
            if SlotRef(z, n) not in INPUTS:  # (a part at a machine input is the machine's)
                routes.append((p, SlotRef(z, n)))
            for q, src in routes:
                targets = OUT if q is PartType.BLUE else [ln.input for ln in LANES if ln.machine == MACHINE_OF[q]]
                every.update(Move(q, src, d) for d in targets)
    every = sorted(every, key=str)
    n_moves = sum({PartType.RED: 3, PartType.GREEN: 2, PartType.BLUE: 1}[state.at(SlotRef(z, n))]
                  - (SlotRef(z, n) in INPUTS) for z in ZONES for n in range(1, 5)
                  if state.at(SlotRef(z, n)) is not None and not (z == "outgoing"))
    best = math.inf

    def rec(seq):
        nonlocal best
        if len(seq) == n_moves:
            f = simulate(seq, state, t, times, first_leg, delay, near)
            best = best if f is None else min(best, f)
            return
        for m in every:
            if simulate(seq + [m], state, t, times, first_leg, delay, near, final=False) is not None:
                rec(seq + [m])

    rec([])
    return best


LEG = st.sampled_from([1.0, 1.5, 2.0, 3.0, 4.5, 6.0])


@st.composite
def small_rounds(draw):
    """A state of at most four moves (greens and blues in incoming, maybe a green at an output or a part in a
    machine), a random table, first legs and a delay."""
    letters = draw(st.lists(st.sampled_from([None, PartType.GREEN, PartType.BLUE]), min_size=4, max_size=4))
    state = FactoryState(tuple(letters), (None,) * 4, (None,) * 4, (None,) * 4)
    extra = draw(st.sampled_from(["none", "green_out", "green_in", "blue_out"]))
    if extra == "green_out":
        state = state.with_slot(OUTPUTS[0], PartType.GREEN)
    elif extra == "green_in":
        state = state.with_slot(next(ln.input for ln in LANES if ln.machine == "machine_B"), PartType.GREEN)
    elif extra == "blue_out":
        state = state.with_slot(next(ln.output for ln in LANES if ln.machine == "machine_B"), PartType.BLUE)
    moves = sum(2 if p is PartType.GREEN else 1 for p in letters if p) + {"none": 0, "green_out": 2,
                                                                           "green_in": 1, "blue_out": 1}[extra]
    if moves == 0 or moves > 4:
        state = FactoryState((PartType.GREEN, None, PartType.BLUE, None), (None,) * 4, (None,) * 4, (None,) * 4)
    table = LegTimes.measure(PICKS, PLACES, lambda a, b, c: draw(LEG))
    first = {r: draw(LEG) for r in PICKS if state.at(r) is not None}
    return state, table, first, draw(st.sampled_from([3.0, 8.0, 15.0]))


@settings(max_examples=40, deadline=None)
@given(small_rounds(), st.booleans())
def test_the_search_finds_the_soonest_order_of_a_brute_force(case, near_rule):
    """With budget enough the search's finish is the least over every sequence of moves and slots, and the
    sequence it returns takes that long by the independent model."""
    state, table, first, delay = case
    near = tuple(reversed(OUT)) if near_rule else ()
    plan = plan_order(POLICY, state, 0.0, table, first_leg=first, delay=delay, near_outputs=near, budget=10 ** 6)
    best = brute_force(state, 0.0, table, first, delay, near)
    if not math.isfinite(best):  # nothing to move now (a part in its machine): the agent waits
        assert plan is None
        return
    assert plan is not None and plan.complete
    assert plan.finish == pytest.approx(best)
    assert simulate(list(plan.moves), state, 0.0, table, first, delay, near) == pytest.approx(plan.finish)


@settings(max_examples=40, deadline=None)
@given(small_rounds())
def test_the_search_from_the_free_orders_first_part_is_as_soon_as_the_free_order(case):
    """The agent skips the second search (``first`` the rules' part) when the exact free search already starts
    with that part: fixing the first part to the free order's own ends exactly as soon."""
    state, table, first, delay = case
    free = plan_order(POLICY, state, 0.0, table, first_leg=first, delay=delay, budget=10 ** 6)
    assume(free is not None)  # nothing to move now (a part in its machine)
    kept = plan_order(POLICY, state, 0.0, table, first_leg=first, delay=delay, budget=10 ** 6,
                      first=free.moves[0].source)
    assert free.complete and kept.complete
    assert kept.moves[0].source == free.moves[0].source
    assert kept.finish == pytest.approx(free.finish)


def test_a_red_part_through_both_machines_waits_for_each():
    """Legs of 2 s, 1 s to pick and to place, delay 5: placed at A at 6 s, green out at 11, placed at B at 15, blue
    out at 20, placed at 24."""
    state = FactoryState.from_letters("RXXX")
    plan = plan_order(POLICY, state, 0.0, uniform(2.0), first_leg={SlotRef("incoming", 1): 2.0}, delay=5.0)
    assert plan.finish == pytest.approx(24.0)
    assert [m.part for m in plan.moves] == [PartType.RED, PartType.GREEN, PartType.BLUE]
    assert plan.moves[2].target.zone == "outgoing"


def test_a_machine_waits_until_its_output_is_taken():
    """A green part at machine A's output, a red one at its input (waiting: the output is full), delay 10, legs of
    2 s. The red one starts when the green one is picked (3 s), so its green comes out at 13, not 10: the last
    blue is placed at 31 (with the machine started at once it would be 28)."""
    a = next(ln for ln in LANES if ln.machine == "machine_A")
    state = FactoryState.from_letters("XXXX").with_slot(a.output, PartType.GREEN).with_slot(a.input, PartType.RED)
    plan = plan_order(POLICY, state, 0.0, uniform(2.0), first_leg={a.output: 2.0}, delay=10.0,
                      placed_at={a.input: -20.0})
    assert plan.finish == pytest.approx(31.0)
    assert simulate(list(plan.moves), state, 0.0, uniform(2.0), {a.output: 2.0}, 10.0) == pytest.approx(31.0)


def test_a_blue_part_from_an_output_goes_to_the_outgoing_slots_near_the_outputs():
    """The outgoing slot fastest to reach is slot 1, but a blue part from machine B's output goes to the first two
    free of ``near_outputs`` (here 4, then 3)."""
    b = next(ln for ln in LANES if ln.machine == "machine_B")
    state = FactoryState.from_letters("XXXX").with_slot(b.output, PartType.BLUE)
    table = LegTimes.measure(PICKS, PLACES, lambda a, t, c: 1.0 if t == OUT[0] else (2.0 if t == OUT[2] else 5.0))
    plan = plan_order(POLICY, state, 0.0, table, first_leg={b.output: 2.0}, delay=5.0,
                      near_outputs=(OUT[3], OUT[2], OUT[1], OUT[0]))
    assert plan.moves[0].target == OUT[2]
    free = plan_order(POLICY, state, 0.0, table, first_leg={b.output: 2.0}, delay=5.0)
    assert free.moves[0].target == OUT[0]


def test_first_fixes_the_first_part_and_the_free_search_is_no_later():
    state = FactoryState.from_letters("BGBX")
    table = LegTimes.measure(PICKS, PLACES, lambda a, b, c: 1.0 + (a.number * 7 + b.number * 3 + c) % 5)
    first = {SlotRef("incoming", n): float(n) for n in (1, 2, 3)}
    free = plan_order(POLICY, state, 0.0, table, first_leg=first, delay=8.0)
    for n in (1, 2, 3):
        kept = plan_order(POLICY, state, 0.0, table, first_leg=first, delay=8.0, first=SlotRef("incoming", n))
        assert kept.moves[0].source == SlotRef("incoming", n)
        assert free.finish <= kept.finish + 1e-9
    assert free.finish == pytest.approx(min(plan_order(POLICY, state, 0.0, table, first_leg=first, delay=8.0,
                                                       first=SlotRef("incoming", n)).finish for n in (1, 2, 3)))


def test_past_its_budget_the_search_still_returns_a_whole_round():
    """Round 3's eight parts with a budget of 10 moves tried: every part placed in its last place (by the model),
    no sooner than the search with a larger budget, and marked not exact."""
    state = FactoryState.from_letters("RGBR").with_slot(OUT[0], None)
    state = FactoryState(state.incoming, (None,) * 4, (None,) * 4, (None,) * 4)
    table = LegTimes.measure(PICKS, PLACES, lambda a, b, c: 1.5 + (a.number + 2 * b.number + c) % 4)
    first = first_legs(state, 2.0)
    quick = plan_order(POLICY, state, 0.0, table, first_leg=first, delay=10.0, budget=10)
    deep = plan_order(POLICY, state, 0.0, table, first_leg=first, delay=10.0, budget=3000)
    assert not quick.complete
    assert len(quick.moves) == 3 + 2 + 1 + 3
    assert simulate(list(quick.moves), state, 0.0, table, first, 10.0) == pytest.approx(quick.finish)
    assert deep.finish <= quick.finish + 1e-9


def test_avoided_parts_are_left_and_a_part_not_in_first_leg_is_not_taken_first():
    state = FactoryState.from_letters("BBXX")
    avoid = {SlotRef("incoming", 1)}
    plan = plan_order(POLICY, state, 0.0, uniform(2.0), first_leg=first_legs(state, 2.0), avoid=avoid)
    assert [m.source for m in plan.moves] == [SlotRef("incoming", 2)]
    only = plan_order(POLICY, state, 0.0, uniform(2.0), first_leg={SlotRef("incoming", 2): 9.0})
    assert only.moves[0].source == SlotRef("incoming", 2) and len(only.moves) == 2
    assert plan_order(POLICY, state, 0.0, uniform(2.0), first_leg={}) is None


# ---------------------------------------------------------------------------------------------- the table
@pytest.fixture(scope="module")
def agent():
    from robotatfactory.agent.behaviour import RoundAgent
    from robotatfactory.robot import load_robot

    return RoundAgent(FIELD, load_robot())


def test_the_table_legs_are_the_planners(agent, tmp_path, monkeypatch):
    """The agent's table (measured here, the cache in a temporary folder) holds the leg planner's times between
    slots: the same as a leg planned and timed from the approach pose, through a grid point when faster."""
    from robotatfactory.agent.obstacles import FieldObstacles

    monkeypatch.setenv("RAF_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(order_mod, "_TABLES", {})
    table = agent._leg_times()
    assert len(table.empty) == len(table.carry) == 64
    assert all(1.0 < v < 20.0 for v in (*table.empty.values(), *table.carry.values()))
    ob = FieldObstacles(FIELD, [])
    for (a, b) in [(OUT[0], SlotRef("incoming", 4)), (INPUTS[0], OUTPUTS[1])]:
        start = agent.legs.path_planner(ob, False).approach_pose(FIELD.slot(a.zone, a.number), agent.d_dock,
                                                                 agent.legs.footprint(False))
        leg, s = agent.legs.timed(ob, start, b, False, "pick")
        assert table.empty[(a, b)] == pytest.approx(agent.legs.faster(ob, start, leg, False, "pick", s)[1])
        assert table.empty[(a, b)] <= s + 1e-9
    files = list(tmp_path.glob("legtimes-*.json"))
    assert len(files) == 1
    assert LegTimes.from_json(json.loads(files[0].read_text())) == table


def test_the_cache_file_is_read_by_the_next_process_and_a_damaged_one_replaced(tmp_path, monkeypatch):
    monkeypatch.setattr(order_mod, "_TABLES", {})
    calls = []

    def measure():
        calls.append(1)
        return uniform(2.5)

    assert leg_times("k1", measure, tmp_path) == uniform(2.5)
    monkeypatch.setattr(order_mod, "_TABLES", {})  # a new process
    assert leg_times("k1", lambda: pytest.fail("measured again"), tmp_path) == uniform(2.5)
    (tmp_path / "legtimes-k2.json").write_text("{not json")
    assert leg_times("k2", measure, tmp_path) == uniform(2.5)
    assert len(calls) == 2
    assert LegTimes.from_json(json.loads((tmp_path / "legtimes-k2.json").read_text())) == uniform(2.5)


def test_the_key_changes_with_what_the_legs_depend_on_only(agent):
    from robotatfactory.agent.behaviour import RoundAgent
    from robotatfactory.agent.settings import agent_settings
    from robotatfactory.robot import load_robot

    keys = []
    for values in ({}, {"tasks": {"state_period": 0.3}, "server": {"port": 4999}}, {"legs": {"via_grid": 0.1}},
                   {"carry": {"v_max": 0.3}}, {"dock": {"place_speed": 0.12}}):
        keys.append(RoundAgent(FIELD, load_robot(), agent_settings(values))._table_key())
    assert keys[0] == keys[1]
    assert len(set(keys)) == 4


def test_the_agent_drives_its_order():
    """A bare round 3 with the order on: every part is placed where the task it was picked for named (the slot is
    not chosen again after the pick), and the round scores the maximum."""
    from robotatfactory.experiments.competition import play_round

    res = play_round(3, 101, record_path=True)
    assert res["max_score"]
    tasks = [text for _, text, *_ in res["events"] if text.startswith("task: move")]
    placed = [text for _, text, *_ in res["events"] if text.startswith("placed the")]
    assert len(tasks) >= len(placed) == res["places"] > 0
    last_task = None
    for _, text, *_ in res["events"]:
        if text.startswith("task: move"):
            last_task = text.rsplit(" to ", 1)[1]
        elif text.startswith("placed the"):
            assert text.rsplit(" in ", 1)[1] == last_task
