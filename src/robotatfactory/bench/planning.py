"""``raf bench planning``: the agent's leg planning, its CPU and its legs' driving time (no simulator, no ROS).

The agent plans a leg (:meth:`~robotatfactory.agent.legs.LegPlanner.plan`: grid A*, the join onto the slot's
normal, the smoothing into arcs) at every decision, several when it chooses a destination by time, and in real
time the robot waits for it. This plans a fixed set: every slot of the four zones from six poses spread over the
field, empty to a pick and carrying to a place as the slot's role allows (``--agent`` settings as in ``raf
experiment competition``), on the nominal map with no part in it, and times each leg's planning (CPU, one core)
and its kinematic drive (:meth:`~robotatfactory.agent.legs.LegPlanner.leg_time`). Each pass plans on
obstacles of its own: the planner remembers its searches with the obstacles (a decision plans the same legs
several times), and a pass on the previous pass's obstacles would time only the memory.

Then the decisions as a round makes them: rounds 1 and 3 of seed 100 on the bare stand-in (ground truth as the
pose, ``--agent`` settings), each control cycle's wall time (the agent's step and the bare simulator's cycle,
about a millisecond): the longest cycle is the choice of a destination after a pick, during which a robot in
real time gets no new command (paced runs wait for it).
"""
from __future__ import annotations

import math
import time

import numpy as np

NAME = "planning"
HELP = ("the agent's leg planning: CPU ms per leg, empty and carrying, and the planned legs' kinematic driving "
        "time, on the nominal map (--agent settings as raf experiment competition's)")
TARGETS = {}

#: start poses (x, y, heading) spread over the field: the start area, mid-field, before each warehouse
POSES = ((-0.24, 0.33, math.pi / 2), (0.0, 0.0, 1.0), (0.3, -0.2, 3.0), (-0.5, -0.3, -1.5), (0.55, 0.3, 2.0),
         (0.1, 0.35, -0.5))


def add_arguments(parser) -> None:
    parser.add_argument("--repeats", type=int, default=3, help="passes over the legs; the median CPU per leg of "
                                                               "the passes is reported (default 3)")
    parser.add_argument("--agent", metavar="NAME=VALUE", action="append", default=[],
                        help="an agent setting (as raf experiment competition's --agent), e.g. legs.arc_join=0 "
                             "(repeatable)")


def legs_to_plan(field):
    """(pose, SlotRef, carrying, dock) for every slot and pose: picks from incoming slots and machine outputs,
    places in outgoing slots and machine inputs."""
    from ..agent.state import ZONES, SlotRef

    out = []
    for zone in ZONES:
        for n in range(1, 5):
            role = field.slot(zone, n).role
            carrying = zone == "outgoing" or role == "input"
            out.extend((pose, SlotRef(zone, n), carrying, "place" if carrying else "pick") for pose in POSES)
    return out


def run(args) -> dict:
    from ..agent.behaviour import RoundAgent
    from ..agent.obstacles import FieldObstacles
    from ..agent.planner import NoPath
    from ..agent.settings import agent_settings
    from ..experiments.competition import parse_agent
    from ..field import load_field
    from ..robot import load_robot

    field, robot = load_field(), load_robot()
    tree = parse_agent(args.agent)
    legs = RoundAgent(field, robot, agent_settings(tree)).legs
    todo = legs_to_plan(field)
    cpu = {False: [], True: []}
    drive = {False: [], True: []}
    failed = 0
    for rep in range(max(1, args.repeats)):
        ob = FieldObstacles(field, [])
        per = {False: [], True: []}
        for pose, ref, carrying, dock in todo:
            t0 = time.process_time()
            try:
                leg = legs.plan(ob, pose, ref, carrying, dock)
            except NoPath:
                failed += rep == 0
                continue
            per[carrying].append(time.process_time() - t0)
            if rep == 0:
                drive[carrying].append(legs.leg_time(leg, pose, carrying))
        for k in per:
            cpu[k].append(float(np.mean(per[k])) if per[k] else math.nan)
        print(f"[bench planning] pass {rep + 1}: {1000 * cpu[False][-1]:.1f} ms a leg empty, "
              f"{1000 * cpu[True][-1]:.1f} ms carrying", flush=True)
    out = {
        "agent_settings": ", ".join(args.agent) if args.agent else "defaults",
        "map": f"{field.name}, nominal, no part in it",
        "legs": len(todo),
        "legs_empty": len(drive[False]),
        "legs_carrying": len(drive[True]),
        "legs_without_path": failed,
        "cpu_ms_per_leg_empty": 1000 * float(np.median(cpu[False])),
        "cpu_ms_per_leg_carrying": 1000 * float(np.median(cpu[True])),
        "drive_s_per_leg_empty_mean": float(np.mean(drive[False])) if drive[False] else math.nan,
        "drive_s_per_leg_carrying_mean": float(np.mean(drive[True])) if drive[True] else math.nan,
        "repeats": max(1, args.repeats),
    }
    out.update(order_cpu(field, robot, agent_settings(tree), max(1, args.repeats)))
    for round_no in (1, 3):
        cycles = round_cycles(round_no, 100, tree)
        print(f"[bench planning] round {round_no} seed 100 (bare): longest cycle {1000 * max(cycles):.0f} ms",
              flush=True)
        out[f"round{round_no}_cycle_ms_max"] = 1000 * max(cycles)
        out[f"round{round_no}_cycle_ms_median"] = 1000 * float(np.median(cycles))
        out[f"round{round_no}_cycles_over_period"] = sum(c > robot.control_period for c in cycles)
        out[f"round{round_no}_cycle_s_over_period_total"] = sum(c for c in cycles if c > robot.control_period)
    return out


def order_cpu(field, robot, settings, repeats: int) -> dict:
    """``tasks.plan_order``'s costs: the leg-time table measured (CPU s, ``repeats`` times, no cache), and the
    first decision of rounds 1-3, seeds 100-109 from the start pose (CPU ms: the pick legs planned from the pose
    and the two searches, :meth:`~robotatfactory.agent.behaviour.RoundAgent._ordered`), with the moves the
    searches tried."""
    from ..agent.behaviour import RoundAgent
    from ..agent.state import FactoryState
    from ..competition.rounds import RoundSetup

    agent = RoundAgent(field, robot, settings)
    table = []
    for rep in range(repeats):
        t0 = time.process_time()
        agent.measure_leg_times()
        table.append(time.process_time() - t0)
        print(f"[bench planning] leg-time table {rep + 1}: {table[-1]:.1f} s CPU", flush=True)
    agent._leg_times()
    pose = (field.start_pose.x, field.start_pose.y, field.start_pose.theta)
    cpu, nodes = [], []
    for round_no in (1, 2, 3):
        for seed in range(100, 110):
            st = FactoryState.from_letters(RoundSetup.make(round_no, seed).letters)
            rules = agent.policy.next_task(st, robot_xy=pose[:2])
            agent._placed = None
            t0 = time.process_time()
            agent._ordered(pose, st, set(), rules)
            cpu.append(time.process_time() - t0)
            nodes.append(agent.order.nodes if agent.order is not None else 0)
    print(f"[bench planning] first decisions with the order: {1000 * float(np.median(cpu)):.0f} ms median, "
          f"{1000 * max(cpu):.0f} max", flush=True)
    return {"order_table_cpu_s_min": min(table), "order_table_cpu_s_max": max(table),
            "order_first_decision_cpu_ms_median": 1000 * float(np.median(cpu)),
            "order_first_decision_cpu_ms_max": 1000 * max(cpu), "order_search_moves_tried_max": max(nodes),
            "order_decisions": len(cpu)}


def round_cycles(round_no: int, seed: int, agent: dict) -> list[float]:
    """Wall seconds of each control cycle of a bare round (the agent's step and the simulator's cycle)."""
    from ..experiments.competition import play_round

    cycles: list[float] = []
    t0 = [0.0]

    def before(sim, agent_) -> None:
        t0[0] = time.perf_counter()

    def after(sim, agent_, command, frame) -> None:
        cycles.append(time.perf_counter() - t0[0])

    play_round(round_no, seed, agent=agent, on_cycle=before, after_cycle=after)
    return cycles
